// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's feedback verdict: a feedback sample goes to a client that asked for its own
// goals' feedback only when its participant requested the goal (_guard_goals.c), whatever Fast DDS
// family asks.
//
// Fast DDS 3.3+ (Lyrical) asks it through public API: _guard_endpoints.c gives an action's feedback
// writer, when rcl creates it, the sample prefilter of fastdds3/_prefilter.cpp, which asks this
// verdict for each sample and each reader whose discovery data (USER_DATA) carries the mark
// CFT_READER_MARK (native/_filter_class.h): the library's clients mark their feedback reader so
// (native/reader/fastdds3/). Every other reader (plain rclpy clients, monitors, `ros2 topic echo`)
// gets every sample, as from an unguarded server. Fast DDS 2.14 (Jazzy) filters feedback through
// the content filter classes instead (_guard_filter.c), and does not ask this.
//
// Soundness rules:
// - No goal is hidden from its client: a goal whose requester is not recorded (taken before the
//   record was cleared, or without rmw's layouts) passes, counted (`unknown`); so does a sample
//   that does not read as plain CDR with a goal UUID (`malformed`).
// - Each verdict marks the write's frame (_guard_status.h): in such writes _guard_heartbeats.c
//   keeps Fast DDS 3.6's HEARTBEAT with the DATA and leaves a reader's GAP for its next DATA, which
//   Fast DDS would otherwise send, each in a datagram of its own, to every reader a sample is
//   withheld from: without that, a server whose feedback writer keeps rclpy's 10 samples spent
//   2.1x plain's CPU per message (N = 16 clients x 4 goals, 36 B); with it 0.42x
//   (docs/BENCHMARKS.md, "Lyrical's Fast DDS 3.6.2"). Those members act on the writing thread
//   only, so an asynchronous publication mode (RMW_FASTRTPS_PUBLICATION_MODE=ASYNCHRONOUS) is not
//   routed, said once (cft_feedback_unroutable).
// - CFT_GUARD_FEEDBACK=off (or 0) leaves every feedback writer as rmw_fastrtps made it.

#include "_guard_feedback.h"

#include <stdlib.h>
#include <string.h>

#include "_cdr.h"
#include "_guard_goals.h"
#include "_guard_status.h"
#include "_guard_text.h"

#define FEEDBACK_SUFFIX "/_action/feedback"

enum { WRITERS, VERDICTS, WITHHELD, UNKNOWN, MALFORMED, COUNTERS };
static unsigned long counters[COUNTERS];
static void count(int which) { __atomic_fetch_add(&counters[which], 1, __ATOMIC_RELAXED); }

bool cft_feedback_wanted(void) { return !cft_env_off("CFT_GUARD_FEEDBACK"); }

const char *cft_feedback_unroutable(void) {
  if (!cft_feedback_wanted()) return "CFT_GUARD_FEEDBACK is off";
  const char *mode = getenv("RMW_FASTRTPS_PUBLICATION_MODE");
  if (mode != NULL && strcmp(mode, "ASYNCHRONOUS") == 0)
    return "RMW_FASTRTPS_PUBLICATION_MODE=ASYNCHRONOUS sends from another thread, where the guard "
           "cannot keep each withheld sample's GAP and HEARTBEAT from costing the server more "
           "than it saves";
  return NULL;
}

bool cft_feedback_is_topic(const char *topic) { return cft_ends_after(topic, FEEDBACK_SUFFIX); }

// 1 when the sample goes to the reader, 0 when not: see the soundness rules.
static int verdict_of(const uint8_t *data, uint32_t length, const uint8_t *reader_guid) {
  // Plain CDR, of either byte order: a uint8[16] needs no alignment.
  uint32_t body_length = 0;
  bool little;
  const uint8_t *body = cft_cdr_bytes(data, length, &body_length, &little);
  if (body == NULL || body_length < CFT_UUID_SIZE) {
    count(MALFORMED);
    return 1;
  }
  switch (cft_goal_owner(body, reader_guid)) {
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

int cft_feedback_verdict(const uint8_t *data, uint32_t length, const uint8_t *reader_guid) {
  count(VERDICTS);
  // The write's frame (_guard_status.h) learns that it asked a routed reader: _guard_heartbeats.c
  // acts on such writes only, on Fast DDS 3.
  cft_write_judged(CFT_KEPT_READER);
  return cft_write_passes(verdict_of(data, length, reader_guid) != 0);
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
