// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's feedback verdict (_guard_feedback.c), for every family's layer.
#ifndef CFT_ACTION_GUARD_FEEDBACK_H_
#define CFT_ACTION_GUARD_FEEDBACK_H_

#include <stdbool.h>
#include <stdint.h>

#ifndef CFT_EXPORT
#define CFT_EXPORT __attribute__((visibility("default")))
#endif

// Whether CFT_GUARD_FEEDBACK leaves the feedback prefilter on (not "off" or "0").
bool cft_feedback_wanted(void);

// Why this process's feedback writers are not to be routed (CFT_GUARD_FEEDBACK off, or an
// asynchronous publication mode), or NULL.
const char *cft_feedback_unroutable(void);

// Whether `topic` (a fully qualified ROS topic name) is an action's feedback topic.
bool cft_feedback_is_topic(const char *topic);

// The decision for a feedback sample (`data`, `length` bytes: the 4-byte encapsulation, then the
// FeedbackMessage, whose goal_id.uuid's 16 bytes come first) and a reader that asked for its own
// goals' feedback only (`reader_guid`, 16 bytes): 0 when another participant requested the goal;
// 1 otherwise (the reader's goal, an unknown goal, or a sample that does not read as plain CDR).
// Counted.
int cft_feedback_verdict(const uint8_t *data, uint32_t length, const uint8_t *reader_guid);

// A family's layer gave a feedback writer the verdict: counted.
void cft_feedback_writer_routed(void);

#endif  // CFT_ACTION_GUARD_FEEDBACK_H_
