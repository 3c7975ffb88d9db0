// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// A goal_id.uuid filter expression compiled to byte masks, and its verdict on 16 uuid bytes.
// Shared by the guard's DDS-SQL accelerator (_guard_filter.c) and the library's own filter class
// (_filter_class.c), which both answer the same grammar:
//     expr   := atom ( AND atom )*  |  atom ( OR atom )*        (one connective per level)
//     atom   := term  |  '(' term ( AND term )* ')'
//     term   := goal_id.uuid[I] = V  |  goal_id.uuid[I] = goal_id.uuid[I]
//     I      := 0..15;   V := a decimal 0..255 without a leading zero, or %N naming such a parameter
// Fast DDS gives AND and OR the same precedence, left to right; a level with one connective means
// the same under any precedence.
#ifndef CFT_ACTION_UUID_PROGRAM_H_
#define CFT_ACTION_UUID_PROGRAM_H_

#include <stdbool.h>
#include <stdint.h>

#ifndef CFT_EXPORT
#define CFT_EXPORT __attribute__((visibility("default")))
#endif

// One clause is a conjunction of byte equalities: it matches when (uuid & mask) == value.
struct clause {
  uint8_t mask[16];
  uint8_t value[16];
};
struct program {
  int count;   // clauses that can match; 0 matches nothing
  struct clause clauses[];
};

// The program of `expression` with `params` (free() it), or NULL when the expression is not in the
// grammar above (or memory ran out).
struct program *cft_uuid_compile(const char *expression, const char *const *params,
                                 int param_count);
bool cft_uuid_matches(const struct program *p, const uint8_t *uuid);

// The 16 bytes of goal_id.uuid in a serialized action FeedbackMessage (a SerializedPayload_t *),
// or NULL when the sample is not plain CDR (encapsulation 0x0000 or 0x0001) of at least 20 bytes,
// or when the build found no Fast DDS headers to take SerializedPayload_t's layout from (then every
// sample passes, and rclpy's own UUID check decides, as for a plain client).
const uint8_t *cft_feedback_uuid(const void *payload);

#endif  // CFT_ACTION_UUID_PROGRAM_H_
