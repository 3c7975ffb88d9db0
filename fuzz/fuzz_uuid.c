// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// libFuzzer harness of the goal_id.uuid grammar and verdict (cft_action/native/_uuid_program.c):
// a remote reader's filter expression and parameters, from its discovery data, compiled by the
// guard's DDS-SQL accelerator and by the CFT_ACTION_UUID class, then judged on a goal UUID.
// Input: 16 bytes of UUID, then NUL-separated: the expression, then up to 100 parameters.
#include <stdlib.h>

#include "_uuid_program.h"
#include "fuzz_common.h"

#define MAX_PARAMETERS 100

int cft_uuid_filter_try(const char *expression, const char *const *params, int param_count,
                        const uint8_t *uuid);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  struct fuzz_in in = {data, size};
  uint8_t uuid[16];
  fuzz_bytes(&in, uuid, sizeof uuid);
  char *expression = fuzz_string(&in, NULL);
  char *params[MAX_PARAMETERS];
  int count = 0;
  while (in.left > 0 && count < MAX_PARAMETERS) params[count++] = fuzz_string(&in, NULL);
  const char *const *p = (const char *const *)params;
  struct program *program = cft_uuid_compile(expression, p, count);
  int verdict = program != NULL ? cft_uuid_matches(program, uuid) : -1;
  if (cft_uuid_filter_try(expression, p, count, uuid) != verdict) abort();  // one answer
  // The class's way: no parameters, so a %N does not compile.
  struct program *plain = cft_uuid_compile(expression, NULL, 0);
  if (plain != NULL) {
    (void)cft_uuid_matches(plain, uuid);
    // A program with clauses matches the UUID its first clause asks for.
    if (plain->count > 0) {
      uint8_t wanted[16];
      for (int i = 0; i < 16; i++)
        wanted[i] = (uint8_t)((uuid[i] & ~plain->clauses[0].mask[i]) | plain->clauses[0].value[i]);
      if (!cft_uuid_matches(plain, wanted)) abort();
    }
  }
  free(plain);
  free(program);
  for (int i = 0; i < count; i++) free(params[i]);
  free(expression);
  return 0;
}
