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

const char *cft_printable(char *out, size_t size, const char *text, size_t length, size_t limit) {
  size_t n = 0;
  const unsigned char *c = (const unsigned char *)text;
  for (size_t i = 0; i < length && c[i] != '\0' && n + 8 < size; i++) {
    if (i == limit) {
      memcpy(out + n, "...", 3);
      n += 3;
      break;
    }
    if (c[i] >= 0x20 && c[i] < 0x7f && c[i] != '\\' && c[i] != '"') out[n++] = (char)c[i];
    else n += (size_t)snprintf(out + n, size - n, "\\x%02x", c[i]);
  }
  out[n] = '\0';
  return out;
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
