// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// See _rate_program.h.
#include "_rate_program.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

// Writers a reader's program tells apart. A writer beyond them is passed unfiltered (as to a plain
// reader); a writer-side program sees one writer only, its own.
#define RATE_WRITERS 64

struct rate_writer {
  uint8_t guid[16];
  bool passed;          // a sample of this writer has passed: next_ns holds
  int64_t next_ns;      // the earliest time the next sample may pass
  uint64_t remaining;   // polled samples still to pass
  uint64_t seen_total;  // the poll total this writer's `remaining` includes
};

struct rate_program {
  int64_t period_ns;
  bool polling;
  uint64_t total, last;
  int writers;
  struct rate_writer writer[RATE_WRITERS];
};

// A decimal of at least one digit, no sign, at most `max`, at *s; advances *s past it. False for
// anything else, a number out of range included (sscanf's would saturate, or wrap a '-').
static bool number(const char **s, uint64_t max, uint64_t *out) {
  const char *p = *s;
  uint64_t v = 0;
  if (*p < '0' || *p > '9') return false;
  for (; *p >= '0' && *p <= '9'; p++) {
    unsigned digit = (unsigned)(*p - '0');
    if (v > (max - digit) / 10) return false;
    v = v * 10 + digit;
  }
  *s = p;
  *out = v;
  return true;
}

static bool literal(const char **s, const char *text) {
  size_t n = strlen(text);
  if (strncmp(*s, text, n) != 0) return false;
  *s += n;
  return true;
}

struct rate_program *cft_rate_compile(const char *expression) {
  if (expression == NULL) return NULL;
  const char *s = expression;
  uint64_t period, total = 0, last = 0;
  if (!literal(&s, "period=") || !number(&s, INT64_MAX, &period)) return NULL;
  bool polling = literal(&s, " poll=");
  if (polling && (!number(&s, UINT64_MAX, &total) || !literal(&s, "/") ||
                  !number(&s, UINT64_MAX, &last) || last > total))
    return NULL;
  if (*s != '\0') return NULL;
  struct rate_program *p = calloc(1, sizeof *p);
  if (p == NULL) return NULL;
  p->period_ns = (int64_t)period;
  p->polling = polling;
  p->total = total;
  p->last = last;
  return p;
}

static const struct rate_writer *known_writer(const struct rate_program *p, const uint8_t *guid) {
  for (int i = 0; i < p->writers; i++)
    if (memcmp(p->writer[i].guid, guid, 16) == 0) return &p->writer[i];
  return NULL;
}

static struct rate_writer *writer_of(struct rate_program *p, const uint8_t *guid) {
  const struct rate_writer *known = known_writer(p, guid);
  if (known != NULL) return (struct rate_writer *)known;
  if (p->writers == RATE_WRITERS) return NULL;
  struct rate_writer *w = &p->writer[p->writers++];
  memcpy(w->guid, guid, 16);
  w->remaining = p->last;
  w->seen_total = p->total;
  return w;
}

// Whether writer `w`'s next sample at `now_ns` passes.
static bool writer_open(const struct rate_program *p, const struct rate_writer *w, int64_t now_ns) {
  if (p->polling && w->remaining == 0) return false;
  return !(p->period_ns > 0 && w->passed && now_ns < w->next_ns);
}

bool cft_rate_open(const struct rate_program *p, const uint8_t *writer_guid, int64_t now_ns) {
  const struct rate_writer *w = known_writer(p, writer_guid);
  // a writer first seen gets the last poll's count; one beyond the table is passed unfiltered
  if (w == NULL) return p->writers == RATE_WRITERS || !p->polling || p->last > 0;
  return writer_open(p, w, now_ns);
}

int64_t cft_rate_now_ns(void) {
  struct timespec now;
  clock_gettime(CLOCK_MONOTONIC, &now);
  return (int64_t)now.tv_sec * 1000000000 + now.tv_nsec;
}

bool cft_rate_decide(struct rate_program *p, const uint8_t *writer_guid, int64_t now_ns) {
  struct rate_writer *w = writer_of(p, writer_guid);
  if (w == NULL) return true;
  if (!writer_open(p, w, now_ns)) return false;
  w->passed = true;
  // period_ns >= 0: only a sum past INT64_MAX can overflow; it saturates (no later sample passes)
  w->next_ns = now_ns > INT64_MAX - p->period_ns ? INT64_MAX : now_ns + p->period_ns;
  if (p->polling) w->remaining--;
  return true;
}

void cft_rate_carry(struct rate_program *to, const struct rate_program *from) {
  to->writers = from->writers;
  memcpy(to->writer, from->writer, sizeof to->writer[0] * (size_t)from->writers);
  for (int i = 0; i < to->writers; i++) {
    struct rate_writer *w = &to->writer[i];
    if (!to->polling) {
      w->remaining = 0, w->seen_total = to->total;
    } else if (!from->polling) {  // polling starts: each writer gets the last poll's count
      w->remaining = to->last, w->seen_total = to->total;
    } else if (to->total >= w->seen_total) {
      w->remaining += to->total - w->seen_total, w->seen_total = to->total;
    }
  }
}
