// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// Where a Fast DDS 2.14 endpoint keeps its protocol times (_endpoint_times.h).
#define _GNU_SOURCE
#include "_endpoint_times.h"

#include <dlfcn.h>
#include <stdbool.h>
#include <string.h>

#define MAX_MOVE 64

// Whether `word` points where an object's vtable pointer points in the vtable named `name`.
static bool is_vptr_of(uintptr_t word, const char *name) {
  Dl_info info;
  return dladdr((void *)word, &info) && info.dli_sname != NULL &&
         strcmp(info.dli_sname, name) == 0 && (uintptr_t)info.dli_saddr + CFT_VTABLE_START == word;
}

uintptr_t cft_endpoint_times(uintptr_t endpoint, size_t endpoint_size, size_t offset,
                             size_t times_size, const char *times_vtable, int *found) {
  uintptr_t member = 0;
  *found = 0;
  for (size_t move = 0; move <= MAX_MOVE && offset + move + times_size <= endpoint_size; move += 8) {
    if (is_vptr_of(*(const uintptr_t *)(endpoint + offset + move), times_vtable)) {
      ++*found;
      member = endpoint + offset + move;
    }
  }
  return *found == 1 ? member : 0;
}
