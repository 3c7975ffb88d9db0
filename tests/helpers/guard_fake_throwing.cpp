// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// A stand-in for libfastrtps whose write throws a C++ exception (as a serialization failure
// would), for the test that the guard unlocks the writer when an exception unwinds through it.
// Like guard_fake_fastdds.c, it defines the three DataWriterImpl members under their Fast DDS 2.x
// mangled names and calls them through the PLT from its own entry points.
#include <stdint.h>

#include <stdexcept>

#define PCNC2 "_ZN8eprosima7fastdds3dds14DataWriterImpl25perform_create_new_changeENS_8fastrtps4rtps12ChangeKind_tEPvRNS4_11WriteParamsERKNS4_16InstanceHandle_tE"
#define PRFI2 "_ZN8eprosima7fastdds3dds14DataWriterImpl26process_reader_filter_infoERKNS_8fastrtps4rtps6GUID_tERKNS4_15ReaderProxyDataE"
#define RRF2 "_ZN8eprosima7fastdds3dds14DataWriterImpl20remove_reader_filterERKNS_8fastrtps4rtps6GUID_tE"

extern "C" {
uint32_t fake_pcnc(void *self, int kind, void *data, void *params, const void *handle) __asm__(PCNC2);
void fake_prfi(void *self, const void *guid, const void *info) __asm__(PRFI2);
void fake_rrf(void *self, const void *guid) __asm__(RRF2);
}

uint32_t fake_pcnc(void *, int kind, void *, void *, const void *) {
  throw std::runtime_error("serialization failed");
  return 40u + (uint32_t)kind;
}
void fake_prfi(void *, const void *, const void *) {}
void fake_rrf(void *, const void *) {}

// Entry points for the test: a write that catches what the member throws, and a filter removal.
extern "C" int fake_write(void *writer, int kind) {
  try {
    return (int)fake_pcnc(writer, kind, 0, 0, 0);
  } catch (const std::exception &) {
    return -1;
  }
}
extern "C" void fake_remove_filter(void *writer) { fake_rrf(writer, 0); }
