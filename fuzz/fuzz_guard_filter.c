// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// libFuzzer harness of a guarded server's reading of a remote reader's filter
// (cft_action/native/guard/_guard_filter.c): the ContentFilterProperty in the reader's discovery
// data (class, related topic, expression, parameters, with its type and topic names and GUID), as
// Fast DDS keeps it in a ReaderProxyData, read where a writer matches the reader; then the
// verdicts on the writer's samples for that reader: the library's classes kept by the guard
// (uuid, node, status) and DDS-SQL filters answered from the uuid bytes; and what it says of a
// filter it refuses.
// Input: the reader's discovery data (fuzz_rpd_read in fuzz_common.h), a byte of flags, then
// samples, each a kind byte, a 2-byte little-endian length and the sample's bytes.
//
// The library's file is compiled into this one, for its static state (the layout it located,
// a failed check that turns the verdicts off for the process), which each input starts without.
#include "_guard_filter.c"  // NOLINT: the real source, not a copy

#include "fuzz_common.h"

// A DataWriterImpl as the guard sees one: its vtable's first slot is the guard's is_relevant.
static bool is_relevant_slot(void) { return true; }
static const void *const writer_vtable[] = {(const void *)is_relevant_slot};
static const struct {
  const void *const *vtable;
} writer = {writer_vtable};

// Fast DDS's DDSFilterExpression::evaluate: the verdicts the guard leaves to Fast DDS.
static bool fastdds_evaluate(const void *self, const void *payload, const void *sample_info,
                             const void *reader_guid) {
  (void)self, (void)payload, (void)sample_info, (void)reader_guid;
  return true;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  static bool enabled_once;
  if (!enabled_once) {
    cft_filter_enable(fastdds_evaluate, (const void *)is_relevant_slot);
    enabled_once = true;
  }
  layout_failed = false;
  layout_located = false;
  shift = 0;
  struct fuzz_in in = {data, size};
  struct fuzz_rpd rpd;
  uint8_t guid[16];
  fuzz_rpd_read(&rpd, &in, guid);
  uint8_t flags = fuzz_byte(&in);
  if (cft_filter_claim_begin(&writer, guid, rpd.info)) {
    // Fast DDS asks for the class's factory only when it would filter for the reader.
    if (flags & 1) (void)cft_filter_claimed(rpd.class_name);
    cft_filter_reader_changed(&writer, guid, rpd.info);
    cft_filter_claim_end();
  } else {
    cft_filter_reader_changed(&writer, guid, rpd.info);
  }
  (void)cft_filter_reader_topic(rpd.info, guid);
  // What the guard refuses (a factory's refusal, a class named like the library's), and how it
  // quotes the remote bytes: said once a process, so quoted here for every input too.
  cft_filter_class_unknown(rpd.class_name);
  if (rpd.expression != NULL) cft_filter_refused(rpd.class_name, rpd.class_name, rpd.expression);
  char quoted[256];
  (void)printable(quoted, sizeof quoted, rpd.expression != NULL ? rpd.expression : "", 40);
  (void)printable(quoted, sizeof quoted, rpd.class_name != NULL ? rpd.class_name : "", 60);
  struct fuzz_change change;
  _Alignas(16) uint8_t sample_info[64] = {0};
  uint64_t sequence = 0;
  while (in.left > 0) {
    uint32_t kind = fuzz_byte(&in) % 4;  // ChangeKind_t: ALIVE and three NOT_ALIVE kinds
    size_t length;
    uint8_t *sample = fuzz_sample(&in, &length);
    static const uint8_t writer_guid[16] = {1, 0x0f, [15] = 0x03};
    fuzz_change(&change, kind, writer_guid, ++sequence, sample, (uint32_t)length);
    (void)cft_filter_relevance(&writer, change.bytes, guid);
    cft_filtering_writer = &writer;
    (void)cft_filter_evaluate(&change, change.bytes + CC_PAYLOAD, sample_info, guid);
    cft_filtering_writer = NULL;
    free(sample);
  }
  // The harness writes the data in one consistent layout: once the guard located it, nothing a
  // remote participant announces may make it doubt the layout (and turn its verdicts off for
  // every reader of the process).
  if (layout_located && layout_failed) {
    fprintf(stderr, "remote data turned the verdicts off: %s\n", layout_report);
    abort();
  }
  cft_filter_reader_dropped(&writer, guid);
  fuzz_rpd_free(&rpd);
  return 0;
}
