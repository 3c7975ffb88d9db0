// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The guard's parts recognise an action's endpoints by the end of their topic, service or type
// names (`/_action/status`, `/_action/send_goal`, `_FeedbackMessage_`), and read the environment
// variables that turn them off.
#ifndef CFT_ACTION_GUARD_TEXT_H_
#define CFT_ACTION_GUARD_TEXT_H_

#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

// Whether the NUL-ended `s` ends with `tail` (or is it).
static inline bool cft_ends_with(const char *s, const char *tail) {
  size_t n = strlen(s), m = strlen(tail);
  return n >= m && strcmp(s + n - m, tail) == 0;
}

// Whether `s` (NULL: no) ends with `tail` after at least one character: an action's topic whose
// name ends so (`<action>/_action/feedback`).
static inline bool cft_ends_after(const char *s, const char *tail) {
  return s != NULL && strlen(s) > strlen(tail) && cft_ends_with(s, tail);
}

// Whether the environment variable `name` turns a part off: "off" or "0".
static inline bool cft_env_off(const char *name) {
  const char *text = getenv(name);
  return text != NULL && (strcmp(text, "off") == 0 || strcmp(text, "0") == 0);
}

#endif  // CFT_ACTION_GUARD_TEXT_H_
