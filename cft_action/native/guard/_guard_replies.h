// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's reply filter (_guard_replies.c), as _guard.c calls it.
#ifndef CFT_ACTION_GUARD_REPLIES_H_
#define CFT_ACTION_GUARD_REPLIES_H_

#include <stdbool.h>
#include <stdint.h>

#ifndef CFT_EXPORT
#define CFT_EXPORT __attribute__((visibility("default")))
#endif

// A reader matched a DataWriterImpl of Fast DDS 2.14 (after the real process_reader_filter_info):
// marks the writer as an action's reply writer when the reader's topic is one.
void cft_replies_reader_matched(const void *writer, const void *reader_guid, const void *reader_info);

// Fast DDS 2.14's DataWriterImpl::is_relevant for a change of a marked reply writer: the
// cft_reply_verdict of its related identity; -1 for any other change (not a reply of a marked
// writer, not ALIVE, or the filter off).
int cft_replies_relevance(const void *change, const void *reader_guid);

// The decision, for every family: whether a reply whose related sample identity is `related`
// (the requester's writer or reader GUID, 16 bytes) and {high, low} (its sequence number) may go to
// the reader `reader_guid` (16 bytes): 0 when it is for another participant than the reader's; -1
// when it goes as Fast DDS sends it (no identity, one that does not read as rmw writes it, or a
// reader of the requesting participant). Counted.
int cft_reply_verdict(const uint8_t *related, int32_t high, uint32_t low,
                      const uint8_t *reader_guid);

// Whether CFT_GUARD_REPLIES leaves the reply filter on (not "off" or "0").
bool cft_replies_wanted(void);
// Whether `service_name` (a ROS service name) is one of an action's three services.
bool cft_replies_is_action_service(const char *service_name);
// A family's layer routes the replies of the service `service_name` with cft_reply_verdict: counted
// as a marked writer.
void cft_replies_writer_routed(const char *service_name);

#endif  // CFT_ACTION_GUARD_REPLIES_H_
