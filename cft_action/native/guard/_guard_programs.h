// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's verdict for readers that mark a program (_guard_programs.c): any writer's, on
// Fast DDS 3.3+.
#ifndef CFT_ACTION_GUARD_PROGRAMS_H_
#define CFT_ACTION_GUARD_PROGRAMS_H_

#include <stdbool.h>
#include <stdint.h>

#ifndef CFT_EXPORT
#define CFT_EXPORT __attribute__((visibility("default")))
#endif

// Why this process's writers are not to be given the verdict (CFT_GUARD_PROGRAMS off), or NULL.
const char *cft_programs_unroutable(void);
// Whether a writer of `topic` may get it: every topic but an action's feedback and status, which
// have routings of their own.
bool cft_programs_is_topic(const char *topic);

// A reader's program, from the value of its mark (CFT_PROGRAM_READER_MARK, native/_filter_class.h:
// "<class> <expression>", `length` bytes): *state becomes the program, with the state of the one it
// replaces carried over (a rate's last passes and polls). 0 when the value is refused (counted,
// said once): *state is then left as it was.
int cft_program_update(void **state, const char *value, uint32_t length);
// The program's decision on a sample (`data`, `length` bytes, encapsulation included) of the
// writer whose routing holds it: 0 when it does not go to the reader. Counted.
int cft_program_judge(void **state, const uint8_t *data, uint32_t length, const uint8_t *reader);
void cft_program_forget(void *state);

// A family's layer gave a writer the verdict: counted.
void cft_programs_writer_routed(void);

#endif  // CFT_ACTION_GUARD_PROGRAMS_H_
