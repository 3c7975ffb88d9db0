// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// libFuzzer harness of a guarded server's status verdict (cft_action/native/guard/_guard_status.c):
// the goal requests it records (a request's goal UUID and the requesting writer's GUID, from any
// client), the CFT_ACTION_STATUS grammar of a remote reader's expression, and the verdict on the
// server's serialized GoalStatusArray samples for that reader (their entries are the goals that
// remote clients sent). Owed samples (a frame of the write, the asking reader owed) are driven too.
// Input: a requester count byte, then per requester 16 bytes of goal UUID and 16 of writer GUID;
// a NUL-ended expression; the reader's 16-byte GUID; a byte of flags (in a write's frame, owed);
// then samples, each a 2-byte little-endian length and its bytes.
//
// The library's file is compiled into this one, for its statics; the record of requesters
// (_guard_goals.c, linked) is emptied after each input.
#include "_guard_status.c"  // NOLINT: the real source, not a copy

#include "fuzz_common.h"

#define MAX_REQUESTERS 8

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  struct fuzz_in in = {data, size};
  int requests = fuzz_byte(&in) % (MAX_REQUESTERS + 1);
  uint8_t uuids[MAX_REQUESTERS][UUID_SIZE];
  for (int i = 0; i < requests; i++) {
    uint8_t guid[16];
    fuzz_bytes(&in, uuids[i], UUID_SIZE);
    fuzz_bytes(&in, guid, sizeof guid);
    cft_goals_record(uuids[i], guid);
  }
  char *expression = fuzz_string(&in, NULL);
  void *program = cft_guard_status_grammar.compile(expression);
  if (program == NULL) program = cft_guard_status_grammar.compile("cft_status_table = 1");
  if (program == NULL) abort();
  uint8_t reader[16];
  fuzz_bytes(&in, reader, sizeof reader);
  uint8_t flags = fuzz_byte(&in);
  struct cft_status_frame f;
  struct fuzz_change change;
  static const uint8_t writer[16] = {1, 0x0f, [15] = 0x03};
  uint64_t sequence = 0;
  while (in.left > 0) {
    size_t length;
    uint8_t *sample = fuzz_sample(&in, &length);
    fuzz_change(&change, 0, writer, ++sequence, sample, (uint32_t)length);
    if (flags & 1) {
      cft_status_frame_open(&f);
      if (flags & 2) f.readers[f.count++] = reader;  // this reader was owed the replaced change
      asking = reader;
      asked_change = change.bytes;
    }
    (void)cft_status_verdict(&program, change.bytes + CC_PAYLOAD, reader);
    if (flags & 1) {
      asking = NULL;
      asked_change = NULL;
      cft_status_frame_close(&f);
    }
    free(sample);
  }
  cft_goals_clear();
  free(program);
  free(expression);
  return 0;
}
