// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's verdict for readers that mark a program: a rate limit and polls
// (CFT_RATE_CLASS, _rate_program.h) or a /parameter_events node filter (CFT_NODE_CLASS,
// _node_program.h), decided in a guarded writer for each reader that asks, whatever Fast DDS
// family asks.
//
// Fast DDS 3.3+ (Lyrical) asks it through public API: _guard_endpoints.c gives every writer that
// rcl creates in a guarded process (but an action's feedback and status writers, which have
// routings of their own) the sample prefilter of fastdds3/_prefilter.cpp, which reads the mark
// CFT_PROGRAM_READER_MARK (native/_filter_class.h) from its readers' discovery data (USER_DATA),
// hands each new value to cft_program_update, and asks cft_program_judge for each sample and
// marked reader. Every other reader gets every sample. The library's rate-limited and polled
// subscriptions and its ParameterEventHandler mark their readers so on Fast DDS 3.3+, where the
// classes cannot be their content filter (cft_action/topics/rate.py); they still decide in their
// own process too, so this verdict only spares the network what they would drop. Fast DDS 2.14
// (Jazzy) evaluates the classes as content filters instead (_filter_class.c), and does not ask.
//
// Soundness rules:
// - A value outside the grammar is refused (counted, said once): the reader then gets every
//   sample, as from an unguarded writer.
// - A rate program's state is the reader's, in this writer: its polls count from what the mark
//   says. The client's marks say a poll's LAST equal to its TOTAL, so that a writer that learns a
//   reader late never passes fewer than the client's own decision would take.
// - An event whose node cannot be read passes (counted: `malformed`).
// - CFT_GUARD_PROGRAMS=off (or 0) leaves every writer as rmw_fastrtps made it.

#include "_guard_programs.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "_filter_class.h"
#include "_guard_feedback.h"
#include "_guard_log.h"
#include "_guard_status.h"
#include "_guard_text.h"
#include "_node_program.h"
#include "_rate_program.h"

enum { WRITERS, VERDICTS, WITHHELD, REFUSED, MALFORMED, COUNTERS };
static unsigned long counters[COUNTERS];
static void count(int which) { __atomic_fetch_add(&counters[which], 1, __ATOMIC_RELAXED); }

const char *cft_programs_unroutable(void) {
  return cft_env_off("CFT_GUARD_PROGRAMS") ? "CFT_GUARD_PROGRAMS is off" : NULL;
}

bool cft_programs_is_topic(const char *topic) {
  return topic != NULL && !cft_feedback_is_topic(topic) && !cft_status_is_topic(topic);
}

// A reader's program: one of the two classes'.
struct program {
  bool rate;      // a rate program, else a node program
  void *program;  // struct rate_program * or struct node_program *
};

static int refused(const char *value, uint32_t length) {
  count(REFUSED);
  static bool said;
  if (cft_first(&said)) {
    char text[256];
    cft_printable(text, sizeof text, value, length, 60);
    cft_say("a reader marked a program outside %s's and %s's grammars: it gets every sample "
            "(\"%s\"; said once, cft_guard_program_count counts each)", CFT_RATE_CLASS,
            CFT_NODE_CLASS, text);
  }
  return 0;
}

int cft_program_update(void **state, const char *value, uint32_t length) {
  const char *space = memchr(value, ' ', length);
  if (space == NULL || memchr(value, '\0', length) != NULL) return refused(value, length);
  size_t class_length = (size_t)(space - value);
  bool rate = class_length == strlen(CFT_RATE_CLASS) &&
              memcmp(value, CFT_RATE_CLASS, class_length) == 0;
  bool node = class_length == strlen(CFT_NODE_CLASS) &&
              memcmp(value, CFT_NODE_CLASS, class_length) == 0;
  char *expression = strndup(space + 1, length - class_length - 1);
  struct program *p = malloc(sizeof *p);
  void *compiled = NULL;
  if (expression != NULL && p != NULL)
    compiled = rate ? (void *)cft_rate_compile(expression)
               : node ? (void *)cft_node_compile(expression) : NULL;
  free(expression);
  if (compiled == NULL) {
    free(p);
    return refused(value, length);
  }
  *p = (struct program){rate, compiled};
  struct program *before = *state;
  if (before != NULL && before->rate && rate) cft_rate_carry(compiled, before->program);
  cft_program_forget(before);
  *state = p;
  return 1;
}

// The one writer a routing's rate programs see: its own (any 16 bytes do).
static const uint8_t THE_WRITER[16];

static bool passes(struct program *p, const uint8_t *data, uint32_t length) {
  if (p->rate) return cft_rate_decide(p->program, THE_WRITER, cft_rate_now_ns());
  uint32_t node_length;
  const char *node = cft_event_node_bytes(data, length, &node_length);
  if (node == NULL) {
    count(MALFORMED);
    return true;
  }
  return cft_node_matches(p->program, node, node_length);
}

int cft_program_judge(void **state, const uint8_t *data, uint32_t length, const uint8_t *reader) {
  (void)reader;
  count(VERDICTS);
  // The write's frame (_guard_status.h) learns that it asked a routed reader: _guard_heartbeats.c
  // then keeps Fast DDS 3's HEARTBEAT with the DATA and leaves the reader's GAP for its next DATA
  // (in whose datagram it rides when that DATA goes to that reader alone), as for feedback.
  cft_write_judged(CFT_KEPT_READER);
  bool passed = passes(*state, data, length);
  if (!passed) count(WITHHELD);
  return cft_write_passes(passed);
}

void cft_program_forget(void *state) {
  struct program *p = state;
  if (p == NULL) return;
  free(p->program);
  free(p);
}

void cft_programs_writer_routed(void) { count(WRITERS); }

// ---- the C API, for ctypes ----------------------------------------------------------------------
// 0: writers given the verdict; 1: verdicts (for marked readers); 2: withheld; 3: marks refused;
// 4: events passed whose node could not be read.
CFT_EXPORT unsigned long cft_guard_program_count(int which) {
  return which >= 0 && which < COUNTERS ? __atomic_load_n(&counters[which], __ATOMIC_RELAXED) : 0;
}
