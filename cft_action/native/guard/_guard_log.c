// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's logging (_guard_log.h).
#define _GNU_SOURCE
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "_guard_log.h"

int cft_debug_enabled(void) {
  const char *v = getenv("CFT_GUARD_DEBUG");
  return v != NULL && v[0] != '\0' && strcmp(v, "0") != 0;
}

bool cft_first(bool *flag) { return !__atomic_exchange_n(flag, true, __ATOMIC_RELAXED); }

void cft_say(const char *fmt, ...) {
  char line[768];
  int n = snprintf(line, sizeof line, "[cft_action guard %d] ", (int)getpid());
  if (n < 0) return;
  va_list ap;
  va_start(ap, fmt);
  int m = vsnprintf(line + n, sizeof line - (size_t)n - 1, fmt, ap);
  va_end(ap);
  if (m < 0) return;
  size_t len = strlen(line);
  line[len++] = '\n';
  ssize_t ignored = write(STDERR_FILENO, line, len);
  (void)ignored;
}
