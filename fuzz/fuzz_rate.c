// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// libFuzzer harness of the rate grammar and its stateful verdict (cft_action/native/_rate_program.c):
// a remote reader's CFT_ACTION_RATE expression, from its discovery data, compiled by a guarded
// writer, decided per sample and carried across the reader's filter updates.
// Input: two NUL-ended expressions (the reader's first, and its update), then operations of
// 10 bytes each: an opcode, a writer (one of 80 GUIDs: more than the program's 64 slots), and a
// time step in ns (the clock is CLOCK_MONOTONIC: any value from 0 to INT64_MAX).
#include <stdint.h>
#include <stdlib.h>

#include "_rate_program.h"
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  struct fuzz_in in = {data, size};
  char *first = fuzz_string(&in, NULL);
  char *update = fuzz_string(&in, NULL);
  struct rate_program *p = cft_rate_compile(first);
  int64_t now = 0;
  while (p != NULL && in.left > 0) {
    uint8_t op = fuzz_byte(&in);
    uint8_t guid[16] = {0x01, 0x0f};
    guid[12] = fuzz_byte(&in) % 80;
    guid[15] = 0x03;  // a user writer
    uint64_t step = fuzz_u64(&in) & (uint64_t)INT64_MAX;
    now = step > (uint64_t)(INT64_MAX - now) ? INT64_MAX : now + (int64_t)step;
    switch (op % 3) {
      case 0: {
        // `open` says what `decide` then decides.
        bool open = cft_rate_open(p, guid, now);
        if (cft_rate_decide(p, guid, now) != open) abort();
        break;
      }
      case 1:
        (void)cft_rate_open(p, guid, now);
        break;
      case 2: {  // the reader's filter is updated in place
        struct rate_program *next = cft_rate_compile(op & 0x80 ? update : first);
        if (next != NULL) {
          cft_rate_carry(next, p);
          free(p);
          p = next;
        }
        break;
      }
    }
  }
  free(p);
  free(update);
  free(first);
  return 0;
}
