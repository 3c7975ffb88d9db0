// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The guard's parts recognise an action's endpoints by the end of their topic, service or type
// names (`/_action/status`, `/_action/send_goal`, `_FeedbackMessage_`).
#ifndef CFT_ACTION_GUARD_TEXT_H_
#define CFT_ACTION_GUARD_TEXT_H_

#include <stdbool.h>
#include <string.h>

// Whether the NUL-ended `s` ends with `tail` (or is it).
static inline bool cft_ends_with(const char *s, const char *tail) {
  size_t n = strlen(s), m = strlen(tail);
  return n >= m && strcmp(s + n - m, tail) == 0;
}

#endif  // CFT_ACTION_GUARD_TEXT_H_
