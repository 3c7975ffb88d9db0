// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's sixth part: an action's status samples go to each of the library's clients
// only when they change the status of a goal its participant requested, or when it is owed one.
//
// An action server's status writer (`rt/<action>/_action/status`, reliable, transient local,
// keep-last 1) publishes a GoalStatusArray that lists every goal the server holds, at every
// transition of any goal, to every client. The library's clients give their status reader a
// filter of CFT_STATUS_CLASS (native/reader/_status_trim.c answers it in the client). Here, in the
// server, _guard_filter.c keeps such a reader out of Fast DDS's filter collection (no signature
// is written for it) and asks cft_status_verdict where the RTPS writer asks whether a change is
// relevant for the reader (DataWriterImpl::is_relevant, once per change and reader of a reliable
// writer, in the write).
//
// Whose goal is it: _guard_goals.c records the participant that requested each goal. A status
// entry goes to a reader if its goal's requester has the reader's GUID prefix, or is not known (a
// goal taken before the record was cleared, or without rmw's layouts): so no goal of a client is
// ever hidden from it.
//
// When a sample passes. The reader's record holds the status of each of its goals in the last
// sample it was passed. A sample passes if it lists one of the reader's goals with another status
// than the record, or one the record lacks; then the record becomes that sample's. A sample lists
// every goal the server holds, so the newest sample passed carries the latest status of each of
// the reader's goals. A new reader starts with an empty record; Fast DDS has already given it the
// history's sample when it matched (ReaderProxy::rtps_is_relevant in matched_reader_add, before
// the writer knows the reader's filter).
//
// Owed samples. With keep-last 1, writing a sample removes the previous one from the history
// (DataWriterHistory::prepare_change -> remove_min_change -> StatefulWriter::change_removed_by_
// history -> ReaderProxy::change_has_been_removed, per reader) before the new change's relevance is
// asked (notify_writer -> unsent_change_added_to_history -> ReaderProxy::rtps_is_relevant ->
// DataWriterImpl::is_relevant), in the same call, on the writing thread, with the writer's mutex
// held throughout (Fast DDS 2.14.5 and 2.14.6). A reader that had been passed the removed change
// and had not acknowledged it (ReaderProxy::change_is_acked is false before the real
// change_has_been_removed: its list holds only changes passed to it and not acknowledged) gets no
// GAP for it, and would miss that transition. So change_has_been_removed is interposed: inside a
// write (a frame, opened by _guard.c's perform_create_new_change wrapper) it records such readers'
// ReaderProxy objects, and rtps_is_relevant (interposed too) says which ReaderProxy asks; a change
// is relevant for an owed reader whatever its content. A chain of owed samples ends at the first
// one the reader acknowledges before the next write. The ReaderProxy pointers are compared within
// one write only, under the writer's mutex, so a pooled ReaderProxy reused for another reader
// never meets a stale pointer.
//
// Owed samples are asked for. An owed sample rarely carries news: the reader's goals have the
// status of the sample it was passed, which it has most likely received, only its acknowledgement
// not yet back (in a burst of transitions the round trip is longer than the writes' spacing, and
// a chain of owed samples went on to the burst's end: N = 16 clients x 4 goals, 59-251 status
// samples per client where 12 changed its goals). So the owed change is relevant for the reader,
// in its ReaderProxy, but not sent with the write: ReaderProxy::change_is_unsent (interposed) says
// it is not unsent for such a reader, after ReaderProxy::from_unsent_to_status marked it
// UNACKNOWLEDGED, as if sent and lost. The next HEARTBEAT that reaches the reader (the periodic
// one, or a status write's widened one, _guard_heartbeats.c part 1) shows it a change it does not
// have; it NACKs, and the writer sends the history's change (ReaderProxy::requested_changes_set
// turns an UNACKNOWLEDGED change REQUESTED), or a GAP if it was replaced, whose successor is owed
// in turn. A reader that did receive its sample has its goals' status all along; one that lost
// it gets the history's change at that HEARTBEAT, as a plain reader gets a lost last sample.
// Only in a write on this thread (a sent change, the NACK response, is not in one), and only for a
// reliable reader whose change was unsent and never delivered (change_is_unsent says so, through
// the flag that reactivates the periodic heartbeat). CFT_GUARD_DEFER_OWED=0 sends owed samples
// with the write.
//
// The status writer heartbeats every STATUS_HEARTBEAT_MS (100) while a reader has not
// acknowledged, instead of Fast DDS's 3 s: that HEARTBEAT is what makes a reader that lost its
// sample ask for the writer's latest (a plain reader gets the burst's next sample anyway). Set with
// StatefulWriter::updateTimes (exported, public; the writer's mutex, recursive, is held by the
// write) on the writer of a status write that judged a kept reader (_guard_heartbeats.c calls
// cft_status_writer with it), once per writer: its vtable pointer must be StatefulWriter's, its
// m_times found as native/_endpoint_times.h says (the headers' offset, or up to 64 B past it in a
// security build) with a period that reads as one; its periodic heartbeat event is then
// restarted, so that a wait already running ends too. CFT_GUARD_STATUS_HEARTBEAT_MS sets the
// period (1 to 3000 ms; `off` leaves Fast DDS's).
//
// A kept reader's record grows with its own goals only.
//
// Fast DDS 3.3+ (Lyrical): the library's clients cannot give their status reader the class there;
// they mark its USER_DATA instead (CFT_STATUS_READER_MARK), and the status writer's public sample
// prefilter (fastdds3/_prefilter.cpp, given by _guard_endpoints.c when rcl creates the publisher)
// asks cft_status_judge for each marked reader, with the record the layer keeps for it. The same
// write order holds there (v3.6.2: prepare_change removes the previous change before
// unsent_change_added_to_history asks ReaderProxy::rtps_is_relevant, whose
// DataWriterImpl::is_relevant asks the prefilter), so change_has_been_removed, rtps_is_relevant
// and change_is_unsent are defined under 3.x's names too, and owed samples are told and deferred
// alike: the change's sequence number as the guard's Fast DDS 3 layer reads it (fastdds3/
// _rtps_types.h), ChangeForReaderStatus_t's UNACKNOWLEDGED the value it has from 3.3 to 3.6.2
// (UNACKNOWLEDGED3). The 100 ms heartbeat is set through public API there: _guard_endpoints.c has
// the layer shorten the status writer's DataWriterQos heartbeat period when it routes it.
//
// Soundness rules:
// - Only where _guard.c locks the Fast DDS 2.14 it knows, with its layouts and rmw's from headers;
//   on Fast DDS 3.3+, only through the layer's prefilter.
// - Only a reader of `rt/.../_action/status` of type action_msgs::msg::dds_::GoalStatusArray_.
// - A sample that does not read as plain CDR GoalStatusArray passes, and empties the record.
// - The interposed Fast DDS members always call the real ones, found in the library that called
//   them.
// - CFT_GUARD_STATUS=off (or 0) turns this file off: every status sample goes to every reader.
// - An owed sample is deferred only where the headers gave CC_SEQUENCE and CFR_UNACKNOWLEDGED, or
//   on Fast DDS 3 where the layer reads changes (it is loaded: the writer is routed).

#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "_cdr.h"
#include "_endpoint_times.h"
#include "_fastdds_layout.h"
#include "_filter_class.h"
#include "_guard_families.h"
#include "_guard_goals.h"
#include "_guard_log.h"
#include "_guard_status.h"
#include "_guard_text.h"

#define CHANGE_REMOVED \
  "_ZN8eprosima8fastrtps4rtps11ReaderProxy23change_has_been_removedERKNS1_16SequenceNumber_tE"
#define CHANGE_IS_ACKED \
  "_ZNK8eprosima8fastrtps4rtps11ReaderProxy15change_is_ackedERKNS1_16SequenceNumber_tE"
#define RTPS_IS_RELEVANT \
  "_ZNK8eprosima8fastrtps4rtps11ReaderProxy16rtps_is_relevantEPNS1_13CacheChange_tE"
// change_is_unsent is const in 2.14.5 and not in 2.14.6 (it updates the run of removed irrelevant
// changes there): two mangled names, one in each library.
#define CHANGE_IS_UNSENT_TAIL \
  "ReaderProxy16change_is_unsentERKNS1_16SequenceNumber_tERjRS3_S5_Rb"
#define CHANGE_IS_UNSENT_CONST "_ZNK8eprosima8fastrtps4rtps11" CHANGE_IS_UNSENT_TAIL
#define CHANGE_IS_UNSENT "_ZN8eprosima8fastrtps4rtps11" CHANGE_IS_UNSENT_TAIL
#define FROM_UNSENT \
  "_ZN8eprosima8fastrtps4rtps11ReaderProxy21from_unsent_to_statusERKNS1_16SequenceNumber_tE" \
  "NS1_23ChangeForReaderStatus_tEbb"

// Fast DDS 3.x's (the same members, in eprosima::fastdds::rtps).
#define CHANGE_REMOVED3 \
  "_ZN8eprosima7fastdds4rtps11ReaderProxy23change_has_been_removedERKNS1_16SequenceNumber_tE"
#define CHANGE_IS_ACKED3 \
  "_ZNK8eprosima7fastdds4rtps11ReaderProxy15change_is_ackedERKNS1_16SequenceNumber_tE"
#define RTPS_IS_RELEVANT3 \
  "_ZNK8eprosima7fastdds4rtps11ReaderProxy16rtps_is_relevantEPNS1_13CacheChange_tE"
#define CHANGE_IS_UNSENT3 "_ZN8eprosima7fastdds4rtps11" CHANGE_IS_UNSENT_TAIL
#define FROM_UNSENT3 \
  "_ZN8eprosima7fastdds4rtps11ReaderProxy21from_unsent_to_statusERKNS1_16SequenceNumber_tE" \
  "NS1_23ChangeForReaderStatus_tEbb"
// ChangeForReaderStatus_t::UNACKNOWLEDGED of Fast DDS 3.3 to 3.6.2 (src/cpp/rtps/writer/
// ChangeForReader.hpp, not installed): UNSENT 0, REQUESTED 1, UNACKNOWLEDGED 2.
#define UNACKNOWLEDGED3 2

#define STATUS_TOPIC_PREFIX "rt/"
#define STATUS_TOPIC_SUFFIX "/_action/status"
#define STATUS_TYPE "action_msgs::msg::dds_::GoalStatusArray_"
#define UUID_SIZE CFT_UUID_SIZE

#if CFT_LAYOUT_KNOWN && defined(RMW_SERVICE_NAME) && defined(RMW_INFO_WRITER_GUID)
#define STATUS_LAYOUT_KNOWN 1
#else
#define STATUS_LAYOUT_KNOWN 0
#endif
#if STATUS_LAYOUT_KNOWN && defined(CC_SEQUENCE) && defined(CFR_UNACKNOWLEDGED)
#define DEFER_LAYOUT_KNOWN 1
#else
#define DEFER_LAYOUT_KNOWN 0
#endif
#if STATUS_LAYOUT_KNOWN && defined(SW_SIZE) && defined(SW_TIMES) && defined(WT_SIZE) && \
    defined(WT_HEARTBEAT_PERIOD) && defined(SW_PERIODIC_HEARTBEAT)
#define WRITER_TIMES_KNOWN 1
#else
#define WRITER_TIMES_KNOWN 0
#endif
#define FASTDDS2_SONAME "libfastrtps.so.2.14"
#define WRITER_UPDATE_TIMES \
  "_ZN8eprosima8fastrtps4rtps14StatefulWriter11updateTimesERKNS1_11WriterTimesE"
#define WRITER_VTABLE "_ZTVN8eprosima8fastrtps4rtps14StatefulWriterE"
#define WRITER_TIMES_VTABLE "_ZTVN8eprosima8fastrtps4rtps11WriterTimesE"
#define TIMED_EVENT_VTABLE "_ZTVN8eprosima8fastrtps4rtps10TimedEventE"
#define CANCEL_TIMER "_ZN8eprosima8fastrtps4rtps10TimedEvent12cancel_timerEv"
#define RESTART_TIMER "_ZN8eprosima8fastrtps4rtps10TimedEvent13restart_timerEv"
#define STATUS_HEARTBEAT_MS 100

enum {
  REQUESTS,     // goal requests recorded with their requester (_guard_goals.c's)
  IMPLAUSIBLE,  // goal requests whose header did not read as a user endpoint's GUID (its)
  VERDICTS,     // verdicts for kept status readers
  CHANGED,      // of those, passed: a goal of the reader changed
  OWED,         // passed: owed, the reader's previous sample was replaced before its ack
  WITHHELD,     // not passed
  UNKNOWN,      // entries of goals whose requester was not known (passed to every reader)
  MALFORMED,    // samples that did not read as a GoalStatusArray (passed)
  RESETS,       // times the requesters' record was full and cleared (_guard_goals.c's)
  KEPT,         // status readers kept by _guard_filter.c (of its `kept`)
  DEFERRED,     // owed changes not sent with the write, left for the reader to ask for
  HEARTBEATS,   // status writers given STATUS_HEARTBEAT_MS
  CONTESTED,    // goal requests for a goal UUID another participant had requested (its)
  COUNTERS
};
static unsigned long counters[COUNTERS];
static void count(int which) { __atomic_fetch_add(&counters[which], 1, __ATOMIC_RELAXED); }

// CFT_GUARD_STATUS: on unless "off" or "0", and only where the guard knows the Fast DDS.
static bool status_on(void) {
  static int on = -1;  // -1: not read yet
  return cft_guard_part_on(&on, "CFT_GUARD_STATUS", STATUS_LAYOUT_KNOWN);
}

// CFT_GUARD_DEFER_OWED: on unless "off" or "0", where the status filter is on (Fast DDS 2.14:
// `fam` 0) or the Fast DDS 3 layer reads changes (1).
static bool defer_on(int fam) {
  if (fam == 0) {
    static int on = -1;
    return DEFER_LAYOUT_KNOWN && cft_guard_part_on(&on, "CFT_GUARD_DEFER_OWED", 1) && status_on();
  }
  static int on3 = -1;  // -1: not read yet
  return cft_guard_env_on(&on3, "CFT_GUARD_DEFER_OWED") && cft_fastdds3_types() != NULL;
}

bool cft_status_keeps(const char *topic, const char *type) {
  return topic != NULL && type != NULL && strncmp(topic, STATUS_TOPIC_PREFIX, 3) == 0 &&
         cft_ends_with(topic, STATUS_TOPIC_SUFFIX) && strcmp(type, STATUS_TYPE) == 0 && status_on();
}

// ---- a kept reader's record: its goals' statuses in the last sample it was passed ---------------
struct record_slot {
  uint8_t uuid[UUID_SIZE];
  int8_t status;
  bool used;
};
struct record {
  unsigned capacity;  // a power of two
  unsigned count;
  struct record_slot slots[];
};

static struct record *record_new(unsigned capacity) {
  struct record *r = calloc(1, sizeof *r + capacity * sizeof r->slots[0]);
  if (r != NULL) r->capacity = capacity;
  return r;
}

static struct record_slot *record_find(struct record *r, const uint8_t *uuid) {
  unsigned mask = r->capacity - 1;
  for (unsigned i = (unsigned)cft_uuid_mix(uuid) & mask;; i = (i + 1) & mask)
    if (!r->slots[i].used || memcmp(r->slots[i].uuid, uuid, UUID_SIZE) == 0) return &r->slots[i];
}

static bool records_this_status(struct record *r, const uint8_t *uuid, int8_t status) {
  const struct record_slot *s = record_find(r, uuid);
  return s->used && s->status == status;
}

// Any expression of the reader's form (`cft_status_table = <n>`): the reader names its own table
// with it, which means nothing here. The program is the reader's record.
static void *status_compile(const char *expression) {
  if (expression == NULL || strncmp(expression, "cft_status_table", 16) != 0) return NULL;
  return record_new(16);
}

const struct cft_filter_grammar cft_guard_status_grammar = {status_compile, NULL, NULL, NULL};

// ---- owed samples: the write's frame ---------------------------------------------------------------
static __thread struct cft_status_frame *frame;  // the innermost write on this thread
static __thread const void *asking;              // the ReaderProxy whose rtps_is_relevant runs
static __thread const uint8_t *asked_change;     // the CacheChange_t it asks about
static __thread int asked_family;                // of which Fast DDS family (0: 2.14, 1: 3.x)
static bool status_readers;  // a status reader was kept: only then are removals looked at

void cft_status_frame_open(struct cft_status_frame *f) {
  f->outer = frame;
  f->count = 0;
  f->overflow = false;
  f->judged = false;
  f->asked = 0;
  f->passed = 0;
  f->deferred_count = 0;
  frame = f;
}

void cft_status_frame_close(struct cft_status_frame *f) { frame = f->outer; }

bool cft_status_write_now(void) { return frame != NULL && frame->judged; }

void cft_write_judged(int reader) {
  if (frame != NULL) frame->asked |= reader;
}

int cft_write_judged_now(void) { return frame != NULL ? frame->asked : 0; }

bool cft_write_passes(bool passed) {
  if (frame != NULL && passed) frame->passed++;
  return passed;
}

int cft_write_passed_now(void) { return frame != NULL ? frame->passed : 0; }

void cft_write_passes_unjudged(void) {
  cft_write_judged(CFT_OTHER_READER);
  cft_write_passes(true);
}

static bool owed(void) {
  if (frame == NULL || asking == NULL) return false;
  if (frame->overflow) return true;
  for (int i = 0; i < frame->count; i++)
    if (frame->readers[i] == asking) return true;
  return false;
}

typedef void (*removed_fn)(void *self, const void *sequence);
typedef bool (*acked_fn)(const void *self, const void *sequence);
typedef bool (*relevant_fn)(const void *self, void *change);
// Each family's real members: [0] Fast DDS 2.14's, [1] 3.x's.
static void *real_removed[2], *real_acked[2], *real_relevant[2];
static const char *const removed_name[2] = {CHANGE_REMOVED, CHANGE_REMOVED3};
static const char *const acked_name[2] = {CHANGE_IS_ACKED, CHANGE_IS_ACKED3};
static const char *const relevant_name[2] = {RTPS_IS_RELEVANT, RTPS_IS_RELEVANT3};

// ReaderProxy::change_has_been_removed of family `fam`, called from `caller`.
static void change_removed(int fam, void *self, const void *sequence, const void *caller) {
  removed_fn real = (removed_fn)cft_guard_real_in_caller(&real_removed[fam], removed_name[fam],
                                                         caller);
  if (frame != NULL && __atomic_load_n(&status_readers, __ATOMIC_RELAXED)) {
    acked_fn acked = (acked_fn)cft_guard_real_in_caller(&real_acked[fam], acked_name[fam], caller);
    if (acked != NULL && !acked(self, sequence)) {
      if (frame->count < CFT_STATUS_FRAME_READERS) frame->readers[frame->count++] = self;
      else frame->overflow = true;
    }
  }
  if (real != NULL) real(self, sequence);
  else cft_say("no real %s: the guard cannot forward it", removed_name[fam]);
}

CFT_EXPORT void cft_change_has_been_removed(void *self, const void *sequence)
    __asm__(CHANGE_REMOVED);
void cft_change_has_been_removed(void *self, const void *sequence) {
  change_removed(0, self, sequence, __builtin_return_address(0));
}

CFT_EXPORT void cft_change_has_been_removed3(void *self, const void *sequence)
    __asm__(CHANGE_REMOVED3);
void cft_change_has_been_removed3(void *self, const void *sequence) {
  change_removed(1, self, sequence, __builtin_return_address(0));
}

struct asking_state {
  const void *reader;
  const uint8_t *change;
  int family;
};
static void restore_asking(const struct asking_state *saved) {
  asking = saved->reader;
  asked_change = saved->change;
  asked_family = saved->family;
}

// ReaderProxy::rtps_is_relevant of family `fam`, called from `caller`.
static bool is_relevant(int fam, const void *self, void *change, const void *caller) {
  relevant_fn real = (relevant_fn)cft_guard_real_in_caller(&real_relevant[fam],
                                                           relevant_name[fam], caller);
  if (real == NULL) return true;  // deliver, as to a reader without a filter
  const struct asking_state saved __attribute__((cleanup(restore_asking))) = {
      asking, asked_change, asked_family};
  asking = self;
  asked_change = change;
  asked_family = fam;
  return real(self, change);
}

CFT_EXPORT bool cft_rtps_is_relevant(const void *self, void *change) __asm__(RTPS_IS_RELEVANT);
bool cft_rtps_is_relevant(const void *self, void *change) {
  return is_relevant(0, self, change, __builtin_return_address(0));
}

CFT_EXPORT bool cft_rtps_is_relevant3(const void *self, void *change) __asm__(RTPS_IS_RELEVANT3);
bool cft_rtps_is_relevant3(const void *self, void *change) {
  return is_relevant(1, self, change, __builtin_return_address(0));
}

// The sequence number of the change asked about: 2.14's at the headers' offset, 3.x's as the
// layer reads it.
static void asked_sequence(uint8_t sequence[CFT_SEQUENCE_SIZE]) {
#if DEFER_LAYOUT_KNOWN
  if (asked_family == 0) {
    memcpy(sequence, asked_change + CC_SEQUENCE, CFT_SEQUENCE_SIZE);
    return;
  }
#endif
  uint8_t writer_guid[CFT_RTPS_GUID_SIZE];
  cft_fastdds3_types()->change_ids(asked_change, sequence, writer_guid);  // defer_on: not NULL
}

// An owed change for the reader asking: relevant, and not sent with this write.
static void defer(void) {
  if (frame == NULL || asking == NULL || asked_change == NULL || !defer_on(asked_family)) return;
  uint8_t sequence[CFT_SEQUENCE_SIZE];
  asked_sequence(sequence);
  if (frame->deferred_count == 0) {
    memcpy(frame->sequence, sequence, CFT_SEQUENCE_SIZE);
  } else if (memcmp(frame->sequence, sequence, CFT_SEQUENCE_SIZE) != 0) {
    return;  // another change in the same write: not expected; it is sent
  }
  if (frame->deferred_count < CFT_STATUS_FRAME_READERS)
    frame->deferred[frame->deferred_count++] = asking;
}

static bool deferred(const void *reader, const void *sequence) {
  if (frame == NULL || frame->deferred_count == 0 ||
      memcmp(frame->sequence, sequence, CFT_SEQUENCE_SIZE) != 0)
    return false;
  for (int i = 0; i < frame->deferred_count; i++)
    if (frame->deferred[i] == reader) return true;
  return false;
}

typedef bool (*unsent_fn)(void *self, const void *sequence, uint32_t *next_fragment, void *gap,
                          const void *min_sequence, bool *reactivate_heartbeat);
typedef void (*from_unsent_fn)(void *self, const void *sequence, int status, bool restart_nack,
                               bool delivered);
static void *real_unsent, *real_unsent_const, *real_unsent3;
// Each family's from_unsent_to_status, and the value of its ChangeForReaderStatus_t's
// UNACKNOWLEDGED (-1: not known).
static void *real_from_unsent[2];
static const char *const from_unsent_name[2] = {FROM_UNSENT, FROM_UNSENT3};
#if DEFER_LAYOUT_KNOWN
static const int unacknowledged[2] = {CFR_UNACKNOWLEDGED, UNACKNOWLEDGED3};
#else
static const int unacknowledged[2] = {-1, UNACKNOWLEDGED3};
#endif

// ReaderProxy::change_is_unsent of family `fam`, for each reader, as the writer delivers a change:
// false for a reader it is deferred for, whose change becomes UNACKNOWLEDGED. Only for one the
// real member found unsent and not yet delivered to a reliable reader (it raised `reactivate`).
static bool change_is_unsent(int fam, void **cache, const char *name, const void *caller,
                             void *self, const void *sequence, uint32_t *next_fragment, void *gap,
                             const void *min_sequence, bool *reactivate) {
  unsent_fn real = (unsent_fn)cft_guard_real_in_caller(cache, name, caller);
  if (real == NULL) {
    cft_say("no real %s: the guard cannot forward it", name);
    return false;
  }
  bool reliable_first = false;
  bool unsent = real(self, sequence, next_fragment, gap, min_sequence, &reliable_first);
  *reactivate |= reliable_first;
  if (unsent && reliable_first && unacknowledged[fam] >= 0 && deferred(self, sequence)) {
    from_unsent_fn to = (from_unsent_fn)cft_guard_real_in_caller(&real_from_unsent[fam],
                                                                 from_unsent_name[fam], caller);
    if (to != NULL) {
      to(self, sequence, unacknowledged[fam], false, false);
      count(DEFERRED);
      return false;
    }
  }
  return unsent;
}

CFT_EXPORT bool cft_change_is_unsent_const(void *self, const void *sequence, uint32_t *next_fragment,
                                           void *gap, const void *min_sequence, bool *reactivate)
    __asm__(CHANGE_IS_UNSENT_CONST);
bool cft_change_is_unsent_const(void *self, const void *sequence, uint32_t *next_fragment,
                                void *gap, const void *min_sequence, bool *reactivate) {
  return change_is_unsent(0, &real_unsent_const, CHANGE_IS_UNSENT_CONST,
                          __builtin_return_address(0), self, sequence, next_fragment, gap,
                          min_sequence, reactivate);
}

CFT_EXPORT bool cft_change_is_unsent(void *self, const void *sequence, uint32_t *next_fragment,
                                     void *gap, const void *min_sequence, bool *reactivate)
    __asm__(CHANGE_IS_UNSENT);
bool cft_change_is_unsent(void *self, const void *sequence, uint32_t *next_fragment, void *gap,
                          const void *min_sequence, bool *reactivate) {
  return change_is_unsent(0, &real_unsent, CHANGE_IS_UNSENT, __builtin_return_address(0), self,
                          sequence, next_fragment, gap, min_sequence, reactivate);
}

CFT_EXPORT bool cft_change_is_unsent3(void *self, const void *sequence, uint32_t *next_fragment,
                                      void *gap, const void *min_sequence, bool *reactivate)
    __asm__(CHANGE_IS_UNSENT3);
bool cft_change_is_unsent3(void *self, const void *sequence, uint32_t *next_fragment, void *gap,
                           const void *min_sequence, bool *reactivate) {
  return change_is_unsent(1, &real_unsent3, CHANGE_IS_UNSENT3, __builtin_return_address(0), self,
                          sequence, next_fragment, gap, min_sequence, reactivate);
}

// ---- the verdict -----------------------------------------------------------------------------------
static uint32_t read_u32(const uint8_t *p, bool little) {
  return little ? (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24
                : (uint32_t)p[3] | (uint32_t)p[2] << 8 | (uint32_t)p[1] << 16 | (uint32_t)p[0] << 24;
}

static size_t align4(size_t offset) { return (offset + 3) & ~(size_t)3; }

// GoalStatus in plain CDR, from the body's start: uint8 uuid[16], int32 sec and uint32 nanosec
// (4-byte aligned), int8 status (as native/reader/_status_trim.c reads it).
static size_t next_entry(size_t pos) { return align4(pos + UUID_SIZE) + 9; }
static int8_t status_at(const uint8_t *body, size_t pos) {
  return (int8_t)body[align4(pos + UUID_SIZE) + 8];
}

// The body offsets of the entries that go to the reader, in a buffer of the thread's.
static __thread size_t *mine;
static __thread size_t mine_capacity;

// The verdict on a sample's CDR body (`body`, `length` bytes, `little` endian; NULL: not plain
// CDR) for a kept reader whose record is *program.
static bool judge_body(void **program, const uint8_t *body, uint32_t length, bool little,
                       const void *reader_guid) {
  struct record *r = *program;
  count(VERDICTS);
  if (frame != NULL) frame->judged = true;
  bool is_owed = owed();
  uint32_t n = 0;
  size_t end = 4;
  if (body != NULL && length >= 4) {
    n = read_u32(body, little);
    for (uint32_t i = 0; i < n && end <= length; i++) end = next_entry(end);
  }
  if (body != NULL && length >= 4 && end <= length && n > mine_capacity) {
    size_t *grown = realloc(mine, n * sizeof *mine);
    if (grown != NULL) mine = grown, mine_capacity = n;
  }
  if (body == NULL || length < 4 || end > length || n > mine_capacity) {
    memset(r->slots, 0, r->capacity * sizeof r->slots[0]);
    r->count = 0;
    count(MALFORMED);
    return true;
  }
  unsigned relevant = 0;
  bool changed = false;
  for (size_t i = 0, pos = 4; i < n; i++, pos = next_entry(pos)) {
    enum cft_goal_owner owner = cft_goal_owner(body + pos, reader_guid);
    if (owner == CFT_GOAL_OTHERS) continue;
    if (owner == CFT_GOAL_UNKNOWN) count(UNKNOWN);
    mine[relevant++] = pos;
    if (!changed && !records_this_status(r, body + pos, status_at(body, pos))) changed = true;
  }
  bool passes = changed || is_owed;
  count(changed ? CHANGED : is_owed ? OWED : WITHHELD);
  if (!passes) return false;
  if (!changed) defer();
  // The record becomes this sample's entries for the reader.
  unsigned capacity = r->capacity;
  while (capacity < 2 * relevant + 2) capacity *= 2;
  if (capacity != r->capacity) {
    struct record *grown = record_new(capacity);
    if (grown == NULL) return true;  // the record stays: later samples pass more often, not less
    free(r);
    *program = r = grown;
  } else {
    memset(r->slots, 0, r->capacity * sizeof r->slots[0]);
  }
  r->count = relevant;
  for (unsigned i = 0; i < relevant; i++) {
    struct record_slot *s = record_find(r, body + mine[i]);
    memcpy(s->uuid, body + mine[i], UUID_SIZE);
    s->status = status_at(body, mine[i]);
    s->used = true;
  }
  return true;
}

bool cft_status_verdict(void **program, const void *payload, const void *reader_guid) {
  uint32_t length = 0;
  bool little = false;
  const uint8_t *body = cft_cdr_body(payload, &length, &little);
  return judge_body(program, body, length, little, reader_guid);
}

// ---- Fast DDS 3.3+: the status writer's prefilter asks (fastdds3/_prefilter.cpp) -----------------
bool cft_status_is_topic(const char *topic) { return cft_ends_after(topic, STATUS_TOPIC_SUFFIX); }

const char *cft_status_unroutable(void) {
  return cft_env_off("CFT_GUARD_STATUS") ? "CFT_GUARD_STATUS is off" : NULL;
}

int cft_status_judge(void **record, const uint8_t *data, uint32_t length, const uint8_t *reader) {
  if (*record == NULL && (*record = record_new(16)) == NULL) return 1;  // no memory: it passes
  cft_write_judged(CFT_KEPT_READER);
  uint32_t body_length = 0;
  bool little = false;
  const uint8_t *body = cft_cdr_bytes(data, length, &body_length, &little);
  return cft_write_passes(judge_body(record, body, body_length, little, reader));
}

void cft_status_forget(void *record) { free(record); }

// ---- the status writer's heartbeat period ---------------------------------------------------------
// CFT_GUARD_STATUS_HEARTBEAT_MS: 0 for `off`, else 1 to 3000 ms (default STATUS_HEARTBEAT_MS).
long cft_status_heartbeat_ms(void) {
  static long period = -1;  // -1: not read yet
  return cft_guard_env_ms(&period, "CFT_GUARD_STATUS_HEARTBEAT_MS", STATUS_HEARTBEAT_MS, 1, 3000) /
         1000000L;
}

void cft_status_heartbeat_set(void) { count(HEARTBEATS); }

#if WRITER_TIMES_KNOWN
static long status_heartbeat_ns(void) { return cft_status_heartbeat_ms() * 1000000L; }

#define SEEN_WRITERS 64
static const void *seen_writers[SEEN_WRITERS];  // looked at once each (a reused address is not)
static int seen_count;
static pthread_mutex_t seen_lock = PTHREAD_MUTEX_INITIALIZER;

static bool first_sight(const void *writer) {
  pthread_mutex_lock(&seen_lock);
  bool first = seen_count < SEEN_WRITERS;
  for (int i = 0; i < seen_count && first; i++) first = seen_writers[i] != writer;
  if (first) seen_writers[seen_count++] = writer;
  pthread_mutex_unlock(&seen_lock);
  return first;
}

typedef void (*writer_update_times_fn)(void *writer, const void *times);
typedef void (*timer_fn)(void *event);
static void *real_writer_update_times, *writer_vtable, *event_vtable, *real_cancel, *real_restart;

// A running timer keeps the period it was started with (TimedEvent::update_interval only sets the
// next one's): the writer's periodic heartbeat event, which precedes m_times by the headers'
// distance (a security build moves both), is cancelled and restarted, as Fast DDS does with the
// writer's mutex held, if it is a TimedEvent.
static void restart_periodic_heartbeat(uintptr_t times_member) {
  const uint8_t *vtable = cft_guard_real(&event_vtable, FASTDDS2_SONAME, TIMED_EVENT_VTABLE);
  timer_fn cancel = (timer_fn)cft_guard_real(&real_cancel, FASTDDS2_SONAME, CANCEL_TIMER);
  timer_fn restart = (timer_fn)cft_guard_real(&real_restart, FASTDDS2_SONAME, RESTART_TIMER);
  void *event;
  memcpy(&event, (const void *)(times_member - SW_TIMES + SW_PERIODIC_HEARTBEAT), sizeof event);
  if (vtable == NULL || cancel == NULL || restart == NULL || event == NULL ||
      *(const uintptr_t *)event != (uintptr_t)(vtable + CFT_VTABLE_START)) {
    cft_say("a status writer's periodic heartbeat is not where the guard looks: its running "
            "period ends as Fast DDS scheduled it");
    return;
  }
  cancel(event);
  restart(event);
}

#endif

void cft_status_writer(void *writer) {
#if WRITER_TIMES_KNOWN
  long period = status_heartbeat_ns();
  if (period == 0 || !status_on() || !first_sight(writer)) return;
  writer_update_times_fn update = (writer_update_times_fn)cft_guard_real(
      &real_writer_update_times, FASTDDS2_SONAME, WRITER_UPDATE_TIMES);
  const uint8_t *vtable = cft_guard_real(&writer_vtable, FASTDDS2_SONAME, WRITER_VTABLE);
  if (update == NULL || vtable == NULL ||
      *(const uintptr_t *)writer != (uintptr_t)(vtable + CFT_VTABLE_START)) {
    cft_say("a status writer is not a StatefulWriter as the guard knows it: it heartbeats as "
            "Fast DDS does");
    return;
  }
  int found;
  uintptr_t member = cft_endpoint_times((uintptr_t)writer, SW_SIZE, SW_TIMES, WT_SIZE,
                                        WRITER_TIMES_VTABLE, &found);
  struct cft_duration current;
  if (member != 0) memcpy(&current, (const void *)(member + WT_HEARTBEAT_PERIOD), sizeof current);
  if (member == 0 || current.seconds < 0 || current.nanosec >= 1000000000u) {
    cft_say("a status writer's times are not where the guard looks (%d found): it heartbeats as "
            "Fast DDS does", found);
    return;
  }
  if ((long)current.seconds * 1000000000L + current.nanosec <= period) return;
  _Alignas(16) unsigned char times[WT_SIZE];
  memcpy(times, (const void *)member, sizeof times);
  struct cft_duration wanted = {(int32_t)(period / 1000000000L),
                                (uint32_t)(period % 1000000000L)};
  memcpy(times + WT_HEARTBEAT_PERIOD, &wanted, sizeof wanted);
  update(writer, times);
  restart_periodic_heartbeat(member);
  count(HEARTBEATS);
#else
  (void)writer;
#endif
}

// Called by _guard_filter.c when it keeps a status reader: removals are looked at from then on.
void cft_status_reader_kept(void) {
  __atomic_store_n(&status_readers, true, __ATOMIC_RELAXED);
  count(KEPT);
}

// ---- the C API, for ctypes -------------------------------------------------------------------------
// In the order of the enum above: 0 requests recorded, 1 implausible request headers, 2 verdicts,
// 3 passed (changed), 4 passed (owed), 5 withheld, 6 entries of unknown requesters, 7 malformed
// samples, 8 resets of the requesters' record, 9 status readers kept, 10 owed changes deferred,
// 11 status writers given the shorter heartbeat period, 12 contested goal requests.
CFT_EXPORT unsigned long cft_guard_status_count(int which) {
  static const int goals[COUNTERS] = {[REQUESTS] = CFT_GOALS_REQUESTS + 1,
                                      [IMPLAUSIBLE] = CFT_GOALS_IMPLAUSIBLE + 1,
                                      [RESETS] = CFT_GOALS_RESETS + 1,
                                      [CONTESTED] = CFT_GOALS_CONTESTED + 1};
  if (which < 0 || which >= COUNTERS) return 0;
  if (goals[which] != 0) return cft_goals_count(goals[which] - 1);
  return __atomic_load_n(&counters[which], __ATOMIC_RELAXED);
}
