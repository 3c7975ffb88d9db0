// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// libFuzzer harness of an action client's status reading (cft_action/native/reader/_status_trim.c):
// a serialized action_msgs/msg/GoalStatusArray from any writer on the status topic, read by the
// CFT_ACTION_STATUS class's verdict in the reader's receive thread and by the trim before Python
// sees it; and the class's grammar (the expression is the client's own, but a guarded server's
// reader of the class compiles remote ones; the client's factory takes whatever Fast DDS hands it).
// Input: a NUL-ended expression; a goal count byte, then per goal 16 bytes of UUID and a byte (its
// fate before the sample: pending, accepted with some early status, or refused); a byte of the
// trim's arguments (which goal is responding, all_pending); then the sample, rest of the input.
// The library's file is compiled into this one, for its table registry: a client has a table per
// action client, so each input starts with none (tables are never renumbered in the library).
#include "_status_trim.c"  // NOLINT: the real source, not a copy

#include "fuzz_common.h"

#define MAX_GOALS 16

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  struct fuzz_in in = {data, size};
  char *expression = fuzz_string(&in, NULL);
  registry_size = 0;
  struct cft_status_table *t = cft_status_table_new();
  if (t == NULL) abort();
  uint8_t goals[MAX_GOALS][16];
  int count = fuzz_byte(&in) % (MAX_GOALS + 1);
  for (int i = 0; i < count; i++) {
    fuzz_bytes(&in, goals[i], 16);
    uint8_t fate = fuzz_byte(&in);
    cft_status_table_sending(t, goals[i]);
    if (fate & 1) (void)cft_status_table_responded(t, goals[i], (fate & 2) != 0);
  }
  uint8_t how = fuzz_byte(&in);
  const uint8_t *responding = count > 0 && (how & 0x80) ? goals[(how & 0x0f) % count] : NULL;
  size_t length;
  uint8_t *sample = fuzz_copy(&in, in.left, &length);
  _Alignas(16) uint8_t payload[64] = {0};
  fuzz_payload(payload, sample, (uint32_t)length);

  // The reader's filter: a remote expression, and the client's own for this table.
  void *remote = cft_status_grammar.compile(expression);
  if (remote != NULL) (void)cft_status_grammar.matches(remote, payload);
  char own[64];
  snprintf(own, sizeof own, "cft_status_table = %lu", cft_status_table_number(t));
  void *program = cft_status_grammar.compile(own);
  if (program == NULL) abort();
  (void)cft_status_grammar.matches(program, payload);

  // The trim writes into a buffer of the sample's size (_rcl.py grows it to at least that).
  uint8_t *out = malloc(length ? length : 1);
  size_t out_length = 0;
  long written = cft_status_trim(t, sample, length, out, &out_length, responding, (how & 0x40) != 0);
  if (written >= 0 && out_length > length) abort();
  (void)cft_status_table_count(t, 3);
  free(out);
  free(program);
  free(remote);
  free(sample);
  cft_status_table_free(t);
  free(expression);
  return 0;
}
