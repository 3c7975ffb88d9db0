// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// libFuzzer harness of a guarded writer's program verdict on Fast DDS 3.3+
// (cft_action/native/guard/_guard_programs.c): a remote reader's program mark (the value after
// CFT_PROGRAM_READER_MARK in its discovery data's USER_DATA, as fastdds3/_prefilter.cpp hands it
// over: "<class> <expression>", not NUL-ended, any bytes), replaced as the reader changes it, and
// the verdicts on the writer's serialized samples for that reader (parameter events, or any sample
// for a rate program). Input: items, each a byte (even: a mark value follows; odd: a sample) and a
// 2-byte little-endian length with that many bytes; at most 64 items.
#include <stdlib.h>

#include "_guard_programs.h"
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  struct fuzz_in in = {data, size};
  void *state = NULL;
  static const uint8_t reader[16] = {1, 0x0f, [15] = 0x04};
  for (int item = 0; item < 64 && in.left > 0; item++) {
    bool mark = (fuzz_byte(&in) & 1) == 0;
    size_t length;
    uint8_t *bytes = fuzz_sample(&in, &length);
    if (mark) {
      void *before = state;
      int taken = cft_program_update(&state, (const char *)bytes, (uint32_t)length);
      if (!taken && state != before) abort();  // a refused value leaves the program as it was
      if (taken && state == NULL) abort();
    } else if (state != NULL) {
      int verdict = cft_program_judge(&state, bytes, (uint32_t)length, reader);
      if (verdict != 0 && verdict != 1) abort();
    }
    free(bytes);
  }
  cft_program_forget(state);
  return 0;
}
