// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// A stand-in for libfastrtps, for tests of the server guard only (tests/test_guard.py builds it).
// It defines the three DataWriterImpl members the guard wraps, under their Fast DDS 2.x mangled
// names, and calls them through the PLT from its own entry points, as Fast DDS does. A "filter
// change" marks the writer busy for a while; a "write" that sees it busy counts an overlap, which
// is the race the guard must rule out.
#include <stdint.h>
#include <time.h>

#define PCNC2 "_ZN8eprosima7fastdds3dds14DataWriterImpl25perform_create_new_changeENS_8fastrtps4rtps12ChangeKind_tEPvRNS4_11WriteParamsERKNS4_16InstanceHandle_tE"
#define PRFI2 "_ZN8eprosima7fastdds3dds14DataWriterImpl26process_reader_filter_infoERKNS_8fastrtps4rtps6GUID_tERKNS4_15ReaderProxyDataE"
#define RRF2 "_ZN8eprosima7fastdds3dds14DataWriterImpl20remove_reader_filterERKNS_8fastrtps4rtps6GUID_tE"

static int busy, overlaps, writes, changes;

static void pause_us(long us) {
  struct timespec ts = {0, us * 1000};
  nanosleep(&ts, 0);
}

static void change(void) {
  __atomic_store_n(&busy, 1, __ATOMIC_SEQ_CST);
  pause_us(300);
  __atomic_store_n(&busy, 0, __ATOMIC_SEQ_CST);
  __atomic_add_fetch(&changes, 1, __ATOMIC_SEQ_CST);
}

uint32_t fake_pcnc(void *self, int kind, void *data, void *params, const void *handle) __asm__(PCNC2);
uint32_t fake_pcnc(void *self, int kind, void *data, void *params, const void *handle) {
  (void)self; (void)data; (void)params; (void)handle;
  int seen = __atomic_load_n(&busy, __ATOMIC_SEQ_CST);
  pause_us(100);
  seen |= __atomic_load_n(&busy, __ATOMIC_SEQ_CST);
  if (seen) __atomic_add_fetch(&overlaps, 1, __ATOMIC_SEQ_CST);
  __atomic_add_fetch(&writes, 1, __ATOMIC_SEQ_CST);
  return 40u + (uint32_t)kind;
}

void fake_prfi(void *self, const void *guid, const void *info) __asm__(PRFI2);
void fake_prfi(void *self, const void *guid, const void *info) { (void)self; (void)guid; (void)info; change(); }

void fake_rrf(void *self, const void *guid) __asm__(RRF2);
void fake_rrf(void *self, const void *guid) { (void)self; (void)guid; change(); }

// Entry points for the test; each reaches the members above through the PLT.
int fake_write(void *writer, int kind) { return (int)fake_pcnc(writer, kind, 0, 0, 0); }
void fake_change_filter(void *writer) { fake_prfi(writer, 0, 0); }
void fake_remove_filter(void *writer) { fake_rrf(writer, 0); }
int fake_overlaps(void) { return __atomic_load_n(&overlaps, __ATOMIC_SEQ_CST); }
int fake_writes(void) { return __atomic_load_n(&writes, __ATOMIC_SEQ_CST); }
int fake_changes(void) { return __atomic_load_n(&changes, __ATOMIC_SEQ_CST); }
