// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's reply filter (_guard_replies.c), as _guard.c calls it.
#ifndef CFT_ACTION_GUARD_REPLIES_H_
#define CFT_ACTION_GUARD_REPLIES_H_

#ifndef CFT_EXPORT
#define CFT_EXPORT __attribute__((visibility("default")))
#endif

// A reader matched a DataWriterImpl of Fast DDS 2.14 (after the real process_reader_filter_info):
// marks the writer as an action's reply writer when the reader's topic is one.
void cft_replies_reader_matched(const void *writer, const void *reader_guid, const void *reader_info);

// DataWriterImpl::is_relevant for a change of a marked reply writer: 0 when the reply is for
// another participant than the reader's; -1 when Fast DDS decides (not a reply of a marked writer,
// no related identity, a reader of the requesting participant, or the filter off).
int cft_replies_relevance(const void *change, const void *reader_guid);

#endif  // CFT_ACTION_GUARD_REPLIES_H_
