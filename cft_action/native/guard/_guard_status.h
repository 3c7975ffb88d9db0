// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's status filter (_guard_status.c), as _guard.c and _guard_filter.c call it.
#ifndef CFT_ACTION_GUARD_STATUS_H_
#define CFT_ACTION_GUARD_STATUS_H_

#include <stdbool.h>
#include <stdint.h>

#ifndef CFT_EXPORT
#define CFT_EXPORT __attribute__((visibility("default")))
#endif

// The grammar under which _guard_filter.c keeps the reader of an action's status topic whose
// filter is of CFT_STATUS_CLASS: its compile gives the reader's record of what it was passed.
extern const struct cft_filter_grammar cft_guard_status_grammar;

// Whether the status filter is on (CFT_GUARD_STATUS, a known Fast DDS 2.14, and rmw's and Fast
// DDS's layouts from the build's headers), and a reader on `topic` with `type` is an action
// status reader that it may keep.
bool cft_status_keeps(const char *topic, const char *type);

// The verdict for a kept status reader on a change's serialized payload: passed when the sample
// changes the status of a goal that the reader's participant requested (or one whose requester is
// not known), or when the reader is owed it (see _guard_status.c). *record is the reader's record,
// which the verdict may move (realloc) as it grows.
bool cft_status_verdict(void **record, const void *payload, const void *reader_guid);

// Fast DDS 3.3+, where the status writer's sample prefilter (fastdds3/_prefilter.cpp, through
// _guard_endpoints.c) asks: whether `topic` (a fully qualified ROS topic name) is an action's
// status topic; why its writer is not to be routed (CFT_GUARD_STATUS off), or NULL; the verdict
// for a reader that asked for its own goals' status (`data`, `length` bytes, encapsulation
// included; *record is the reader's, made at its first verdict, which cft_status_forget frees),
// told to the write's frame as _guard_feedback.c's.
bool cft_status_is_topic(const char *topic);
const char *cft_status_unroutable(void);
int cft_status_judge(void **record, const uint8_t *data, uint32_t length, const uint8_t *reader);
void cft_status_forget(void *record);

// The StatefulWriter of a write that judged a kept status reader (cft_status_write_now), as
// _guard_heartbeats.c sees it: heartbeats every CFT_GUARD_STATUS_HEARTBEAT_MS from now on.
void cft_status_writer(void *writer);

// CFT_GUARD_STATUS_HEARTBEAT_MS: the status writers' heartbeat period, in ms (0: Fast DDS's). On
// Fast DDS 3.3+ _guard_endpoints.c has the layer set it when it routes a status writer, and tells
// cft_status_heartbeat_set.
long cft_status_heartbeat_ms(void);
void cft_status_heartbeat_set(void);

// _guard_filter.c kept a status reader: from now on the writes' removals are looked at.
void cft_status_reader_kept(void);

// One write (perform_create_new_change) of one writer: the readers that a change the write removed
// from the history had been passed to and had not acknowledged. Opened and closed by _guard.c's
// wrapper, on the writing thread, with the writer's mutex held by Fast DDS inside it.
#define CFT_STATUS_FRAME_READERS 64
#define CFT_SEQUENCE_SIZE 8  // a SequenceNumber_t: {int32 high, uint32 low}, as on the wire
struct cft_status_frame {
  struct cft_status_frame *outer;  // a write nested in this one's (statistics writers)
  int count;
  bool overflow;                   // more than CFT_STATUS_FRAME_READERS: every reader is owed
  bool judged;                     // a kept status reader's verdict ran in this write
  int asked;                       // CFT_KEPT_READER | CFT_OTHER_READER: whose relevance it asked
  int passed;                      // the readers it found the change relevant for
  const void *readers[CFT_STATUS_FRAME_READERS];  // ReaderProxy objects, compared, never read
  // The readers passed this write's change only because they were owed it: it is not sent to
  // them now (see _guard_status.c, "Owed samples are asked for").
  int deferred_count;
  unsigned char sequence[CFT_SEQUENCE_SIZE];        // the change's SequenceNumber_t
  const void *deferred[CFT_STATUS_FRAME_READERS];  // ReaderProxy objects, compared, never read
};
void cft_status_frame_open(struct cft_status_frame *frame);
void cft_status_frame_close(struct cft_status_frame *frame);

// Whether the write running on this thread is one whose change a kept status reader was judged
// on (a status writer's): _guard_heartbeats.c heartbeats all its readers, as their
// acknowledgements end the owed chains.
bool cft_status_write_now(void);

// Whose relevance was asked in the write on this thread: a reader that _guard_filter.c keeps, or
// another (_guard.c's is_relevant says so), and both: _guard_heartbeats.c spaces out the piggyback
// HEARTBEATs of a write that had both.
#define CFT_KEPT_READER 1
#define CFT_OTHER_READER 2
void cft_write_judged(int reader);
int cft_write_judged_now(void);
// How many readers the write on this thread found its change relevant for: _guard.c's is_relevant
// counts each verdict (returning it), _guard_heartbeats.c merges a personal GAP into a DATA that
// goes to that reader alone.
bool cft_write_passes(bool passed);
int cft_write_passed_now(void);
// A reader that a Fast DDS 3 routing passed without a verdict (fastdds3/_prefilter.h): another
// reader asked, and one more passed.
void cft_write_passes_unjudged(void);

#endif  // CFT_ACTION_GUARD_STATUS_H_
