// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's logging, used by every part of the guard and depending on none of them.
#ifndef CFT_ACTION_GUARD_LOG_H_
#define CFT_ACTION_GUARD_LOG_H_

#include <stdbool.h>
#include <stddef.h>

// One line on stderr, "[cft_action guard <pid>] ...", written with one write(2) so that lines of
// different threads do not interleave.
__attribute__((format(printf, 1, 2))) void cft_say(const char *fmt, ...);

// True the first time it is called with `flag` (false before), then false: for what is said once.
bool cft_first(bool *flag);

// `text` (remote bytes, `length` of them, or up to a NUL) for a log line, into `out`: printable
// ASCII as is, any other byte as \xNN, at most `limit` bytes of it, then "..." if there was more.
const char *cft_printable(char *out, size_t size, const char *text, size_t length, size_t limit);

// 1 when CFT_GUARD_DEBUG is set (and not "0"): say what the guard does, not only what went wrong.
int cft_debug_enabled(void);

#endif  // CFT_ACTION_GUARD_LOG_H_
