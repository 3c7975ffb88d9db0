// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// What the guard's parts call in cft_action/native/guard/_guard_families.c (_guard_families.h), for
// the guard harnesses: that file decides whether the loaded Fast DDS is one the guard knows, which
// needs that library. Here the guard always knows it (every part whose
// layouts the headers gave is on), and finds no Fast DDS member to call.
#include <stddef.h>

#include "_guard_families.h"

int cft_guard_knows_fastdds2(void) { return 1; }

bool cft_guard_part_on(int *cache, const char *env, bool usable) {
  (void)cache, (void)env;
  return usable;
}

bool cft_guard_env_on(int *cache, const char *env) {
  (void)cache, (void)env;
  return true;
}

long cft_guard_ms_to_ns(const char *text, long min_ms, long max_ms) {
  (void)text, (void)min_ms, (void)max_ms;
  return -1;
}

long cft_guard_env_ms(long *cache, const char *env, long fallback_ms, long min_ms, long max_ms) {
  (void)cache, (void)env, (void)min_ms, (void)max_ms;
  return fallback_ms * 1000000L;
}

void *cft_guard_real(void **cache, const char *soname, const char *name) {
  (void)cache, (void)soname, (void)name;
  return NULL;
}

void *cft_guard_loaded_symbol(const char *name, const char *prefer) {
  (void)name, (void)prefer;
  return NULL;
}

void *cft_guard_real_in_caller(void **cache, const char *name, const void *return_address) {
  (void)cache, (void)name, (void)return_address;
  return NULL;
}

const struct cft_rtps_types *cft_fastdds3_types(void) { return NULL; }
