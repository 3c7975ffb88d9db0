// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's feedback verdict: a feedback sample goes to a client that asked for its own
// goals' feedback only when its participant requested the goal (_guard_goals.c), whatever Fast DDS
// family asks.
//
// Fast DDS 3.3+ (Lyrical) asks it through public API, with CFT_GUARD_FEEDBACK=on:
// _guard_endpoints.c gives an action's feedback writer, when rcl creates it, the sample prefilter
// of fastdds3/_prefilter.cpp, which asks this verdict for each sample and each reader whose
// discovery data (USER_DATA) carries the mark CFT_READER_MARK (native/_filter_class.h): the
// library's clients mark their feedback reader so (native/reader/fastdds3/). Every other reader
// (plain rclpy clients, monitors, `ros2 topic echo`) gets every sample, as from an unguarded
// server. Fast DDS 2.14 (Jazzy) filters feedback through the content filter classes instead
// (_guard_filter.c), and does not ask this.
//
// Soundness rules:
// - No goal is hidden from its client: a goal whose requester is not recorded (taken before the
//   record was cleared, or without rmw's layouts) passes, counted (`unknown`); so does a sample
//   that does not read as plain CDR with a goal UUID (`malformed`).
// - Opt-in: only CFT_GUARD_FEEDBACK=on (or 1) routes feedback. Fast DDS 3.6.2 sent a reader about
//   two GAP or HEARTBEAT datagrams per sample withheld from it (the 2.14 guard merges a reader's
//   GAP into its next DATA: _guard.c), so a server whose feedback writer keeps rclpy's 10 samples,
//   N = 16 clients x 4 goals, spent 2.1x plain's CPU per message at 36 B and 1.2x at 4 kB, and
//   reached 0.47x plain's rate at 36 B (docs/BENCHMARKS.md, "Lyrical's Fast DDS 3.6.2"). Otherwise
//   every feedback writer stays as rmw_fastrtps made it, and the library's clients behave as plain
//   rclpy's.

#include "_guard_feedback.h"

#include <stdlib.h>
#include <string.h>

#include "_guard_goals.h"
#include "_guard_text.h"

#define FEEDBACK_SUFFIX "/_action/feedback"
#define ENCAPSULATION_SIZE 4

enum { WRITERS, VERDICTS, WITHHELD, UNKNOWN, MALFORMED, COUNTERS };
static unsigned long counters[COUNTERS];
static void count(int which) { __atomic_fetch_add(&counters[which], 1, __ATOMIC_RELAXED); }

bool cft_feedback_wanted(void) {
  const char *text = getenv("CFT_GUARD_FEEDBACK");
  return text != NULL && (strcmp(text, "on") == 0 || strcmp(text, "1") == 0);
}

bool cft_feedback_is_topic(const char *topic) {
  return topic != NULL && strlen(topic) > strlen(FEEDBACK_SUFFIX) &&
         cft_ends_with(topic, FEEDBACK_SUFFIX);
}

int cft_feedback_verdict(const uint8_t *data, uint32_t length, const uint8_t *reader_guid) {
  count(VERDICTS);
  // Plain CDR, big (0x0000) or little endian (0x0001): a uint8[16] needs no alignment.
  if (data == NULL || length < ENCAPSULATION_SIZE + CFT_UUID_SIZE || data[0] != 0 || data[1] > 1) {
    count(MALFORMED);
    return 1;
  }
  switch (cft_goal_owner(data + ENCAPSULATION_SIZE, reader_guid)) {
    case CFT_GOAL_OTHERS:
      count(WITHHELD);
      return 0;
    case CFT_GOAL_UNKNOWN:
      count(UNKNOWN);
      return 1;
    default:
      return 1;
  }
}

void cft_feedback_writer_routed(void) {
  count(WRITERS);
}

// ---- the C API, for ctypes -----------------------------------------------------------------------
// 0: feedback writers given the verdict; 1: verdicts (for marked readers); 2: withheld (another
// participant's goal); 3: passed, the goal's requester not known; 4: passed, not plain CDR.
CFT_EXPORT unsigned long cft_guard_feedback_count(int which) {
  return which >= 0 && which < COUNTERS ? __atomic_load_n(&counters[which], __ATOMIC_RELAXED) : 0;
}
