// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// A rate limit and a poll count, decided per writer, for the CFT_ACTION_RATE class
// (_filter_class.h). Its expressions are the ones cft_action.topics.rate writes:
//     expr := 'period=' NS [ ' poll=' TOTAL '/' LAST ]
// NS, TOTAL and LAST are decimal digits without a sign, NS at most INT64_MAX, the others at most
// UINT64_MAX, LAST at most TOTAL; anything else (an out-of-range number too) does not compile.
// NS: at most one sample per NS nanoseconds passes from each writer (0: no rate limit); the sample
// that passes is the first one at least NS after the last that passed. With poll=: only polled
// samples pass, TOTAL is the sum of every poll's count so far and LAST the last poll's count. A
// writer known to the program gets TOTAL minus the total it had seen more samples; a writer first
// seen gets LAST (each publisher's next LAST samples). Unlike the other classes the verdict has
// state: it is decided once per sample, where the filter runs (a writer: when the sample is
// written; a reader: when it is received), and is not the same for the same sample twice.
#ifndef CFT_ACTION_RATE_PROGRAM_H_
#define CFT_ACTION_RATE_PROGRAM_H_

#include <stdbool.h>
#include <stdint.h>

struct rate_program;

// The program of `expression` (free() it), or NULL outside the grammar (or out of memory).
struct rate_program *cft_rate_compile(const char *expression);
// The verdict on a sample of the writer whose GUID is `writer_guid` (16 bytes), received or written
// at `now_ns` (CLOCK_MONOTONIC); updates the writer's state. Not thread-safe: the caller holds
// the filter's lock exclusively.
bool cft_rate_decide(struct rate_program *p, const uint8_t *writer_guid, int64_t now_ns);
// The clock of the verdicts: CLOCK_MONOTONIC, in ns.
int64_t cft_rate_now_ns(void);
// Whether a sample of that writer at `now_ns` would pass, without deciding it (no state changes).
// The caller holds the filter's lock, shared at least.
bool cft_rate_open(const struct rate_program *p, const uint8_t *writer_guid, int64_t now_ns);
// Give `to` (a program compiled from an update) the writers' state of `from`, the program it
// replaces: their last passes, and their poll counts grown by what the update polled.
void cft_rate_carry(struct rate_program *to, const struct rate_program *from);

#endif  // CFT_ACTION_RATE_PROGRAM_H_
