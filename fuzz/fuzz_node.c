// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// libFuzzer harness of the node-name grammar and the parameter event reader
// (cft_action/native/_node_program.c): a remote reader's CFT_ACTION_NODE expression, from its
// discovery data, and a serialized rcl_interfaces/msg/ParameterEvent from any writer on the domain.
// Input: the expression, a NUL, then the sample's bytes (with their encapsulation header).
#include <stdlib.h>

#include "_node_program.h"
#include "fuzz_common.h"

int cft_node_filter_try(const char *expression, const void *payload);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  struct fuzz_in in = {data, size};
  char *expression = fuzz_string(&in, NULL);
  size_t length;
  uint8_t *sample = fuzz_copy(&in, in.left, &length);
  _Alignas(16) uint8_t payload[64] = {0};
  fuzz_payload(payload, sample, (uint32_t)length);
  uint32_t node_length = 0;
  const char *node = cft_event_node(payload, &node_length);
  if (node != NULL && (node < (const char *)sample || node + node_length >= (const char *)sample + length))
    abort();  // the name and its terminator lie inside the sample
  struct node_program *program = cft_node_compile(expression);
  int verdict = node == NULL ? -2 : program == NULL ? -1 : cft_node_matches(program, node, node_length);
  if (cft_node_filter_try(expression, payload) != verdict) abort();
  if (program != NULL) (void)cft_node_matches(program, expression, 0);
  free(program);
  free(sample);
  free(expression);
  return 0;
}
