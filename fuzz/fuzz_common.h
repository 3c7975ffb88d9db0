// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// What every libFuzzer harness in fuzz/ shares: a reader of the fuzzer's input, and the Fast DDS
// objects that the library reads another participant's bytes from, built at the offsets of the
// generated _fastdds_layout.h (the same header setup.py writes; `make fuzz` generates it):
//   - a SerializedPayload_t (length, data, max_size) around a sample's bytes;
//   - a CacheChange_t (kind, writerGUID, sequenceNumber, serializedPayload) around one;
//   - a ReaderProxyData (m_guid, m_key, topic and type names, the ContentFilterProperty).
// Every buffer a harness hands the library is malloc'd at its exact size, so that AddressSanitizer
// sees a read one byte past what the remote participant sent.
#ifndef CFT_ACTION_FUZZ_COMMON_H_
#define CFT_ACTION_FUZZ_COMMON_H_

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "_fastdds_layout.h"

#if !CFT_LAYOUT_KNOWN
#error "fuzz/ needs _fastdds_layout.h from Fast DDS headers: run `make fuzz`, which generates it"
#endif

// ---- the fuzzer's input, consumed from the front --------------------------------------------------
struct fuzz_in {
  const uint8_t *at;
  size_t left;
};

static inline uint8_t fuzz_byte(struct fuzz_in *in) {
  if (in->left == 0) return 0;
  in->left--;
  return *in->at++;
}

// Up to n bytes into out, zero-filled past the input's end.
static inline void fuzz_bytes(struct fuzz_in *in, void *out, size_t n) {
  size_t k = n < in->left ? n : in->left;
  memcpy(out, in->at, k);
  memset((uint8_t *)out + k, 0, n - k);
  in->at += k;
  in->left -= k;
}

static inline uint64_t fuzz_u64(struct fuzz_in *in) {
  uint64_t v;
  fuzz_bytes(in, &v, sizeof v);
  return v;
}

// The bytes up to the next NUL (or the end), as a malloc'd string of exactly that size; the NUL is
// consumed. *length: its bytes without the terminator.
static inline char *fuzz_string(struct fuzz_in *in, size_t *length) {
  const uint8_t *end = memchr(in->at, '\0', in->left);
  size_t n = end != NULL ? (size_t)(end - in->at) : in->left;
  char *s = malloc(n + 1);
  if (s == NULL) abort();
  memcpy(s, in->at, n);
  s[n] = '\0';
  in->at += n + (end != NULL);
  in->left -= n + (end != NULL);
  if (length != NULL) *length = n;
  return s;
}

// The next `n` bytes (fewer at the end) as a malloc'd copy of exactly that size (at least 1 byte,
// so that malloc(0) never decides); *length: how many.
static inline uint8_t *fuzz_copy(struct fuzz_in *in, size_t n, size_t *length) {
  if (n > in->left) n = in->left;
  uint8_t *p = malloc(n ? n : 1);
  if (p == NULL) abort();
  memcpy(p, in->at, n);
  in->at += n;
  in->left -= n;
  *length = n;
  return p;
}

// A sample: a 2-byte little-endian length, then that many bytes (the rest when fewer).
static inline uint8_t *fuzz_sample(struct fuzz_in *in, size_t *length) {
  size_t n = fuzz_byte(in);
  n |= (size_t)fuzz_byte(in) << 8;
  return fuzz_copy(in, n, length);
}

// ---- Fast DDS objects, at the headers' offsets -----------------------------------------------------
static inline void fuzz_put_u32(uint8_t *at, uint32_t v) { memcpy(at, &v, sizeof v); }
static inline void fuzz_put_ptr(uint8_t *at, const void *p) { memcpy(at, &p, sizeof p); }

// A SerializedPayload_t at `payload` holding `data` (`length` bytes).
static inline void fuzz_payload(uint8_t *payload, const uint8_t *data, uint32_t length) {
  fuzz_put_u32(payload + PAYLOAD_LENGTH, length);
  fuzz_put_ptr(payload + PAYLOAD_DATA, data);
  fuzz_put_u32(payload + PAYLOAD_MAX_SIZE, length);
}

// A CacheChange_t: room for every member the library reads (the headers' largest offset and more).
#define FUZZ_CHANGE_SIZE 1024
_Static_assert(CC_RELATED_SEQUENCE + 8 <= FUZZ_CHANGE_SIZE && CC_PAYLOAD + 64 <= FUZZ_CHANGE_SIZE,
               "FUZZ_CHANGE_SIZE is smaller than the headers' CacheChange_t members");
struct fuzz_change {
  _Alignas(16) uint8_t bytes[FUZZ_CHANGE_SIZE];
};

// An ALIVE change (`kind` as given) of the writer `writer_guid` with sequence number `sequence`.
static inline void fuzz_change(struct fuzz_change *c, uint32_t kind, const uint8_t *writer_guid,
                               uint64_t sequence, const uint8_t *data, uint32_t length) {
  memset(c->bytes, 0, sizeof c->bytes);
  memcpy(c->bytes + CC_KIND, &kind, CC_KIND_SIZE);
  memcpy(c->bytes + CC_WRITER_GUID, writer_guid, 16);
  memcpy(c->bytes + CC_SEQUENCE, &sequence, sizeof sequence);
  fuzz_payload(c->bytes + CC_PAYLOAD, data, length);
}

// A ReaderProxyData, `FUZZ_RPD_MARGIN` bytes into a zeroed buffer with as many after it: the
// library looks for m_guid up to 64 bytes either side of the headers' offset (a security build's).
#define FUZZ_RPD_MARGIN 128
struct fuzz_rpd {
  uint8_t *buffer;  // RPD_SIZE + 2 * FUZZ_RPD_MARGIN bytes
  uint8_t *info;    // the object
  int shift;        // how far m_guid and every later member moved from the headers' offsets
  const char *class_name;  // the filter class, as Fast DDS hands it to find_content_filter_factory
  char *expression;
  uint8_t *parameters;
};

// A fixed_string<255> at `at` holding the bytes of `text` up to its first NUL, cut at 255, as
// Fast DDS's own assignment keeps it.
static inline void fuzz_string255(uint8_t *at, const char *text) {
  size_t n = strnlen(text, 255);
  memcpy(at, text, n);
  at[n] = '\0';
  memcpy(at + STRING255_LENGTH, &n, sizeof n);
}

// Reads a reader's discovery data from the input: a shift byte (m_guid and m_key moved by a multiple
// of 4 bytes, as in a security build), its 16-byte GUID, a parameter count byte, then NUL-ended:
// the type name, topic name, filter class and related topic; the expression (a 2-byte
// little-endian length and its bytes); each parameter, NUL-ended.
static inline void fuzz_rpd_read(struct fuzz_rpd *r, struct fuzz_in *in, uint8_t *guid) {
  r->buffer = calloc(1, RPD_SIZE + 2 * FUZZ_RPD_MARGIN);
  if (r->buffer == NULL) abort();
  r->info = r->buffer + FUZZ_RPD_MARGIN;
  int shift = r->shift = ((int)(fuzz_byte(in) % 33) - 16) * 4;  // -64..64
  fuzz_bytes(in, guid, 16);
  memcpy(r->info + RPD_GUID + shift, guid, 16);
  memcpy(r->info + RPD_KEY + shift, guid, 16);
  int parameters = fuzz_byte(in) % 101;  // Fast DDS keeps at most 100
  uint8_t *cfp = r->info + RPD_CONTENT_FILTER + shift;
  static const long strings[] = {RPD_TYPE_NAME, RPD_TOPIC_NAME};
  for (int i = 0; i < 2; i++) {
    char *s = fuzz_string(in, NULL);
    fuzz_string255(r->info + strings[i] + shift, s);
    free(s);
  }
  char *s = fuzz_string(in, NULL);
  fuzz_string255(cfp + CFP_CLASS_NAME, s);
  r->class_name = (const char *)cfp + CFP_CLASS_NAME;
  free(s);
  s = fuzz_string(in, NULL);
  fuzz_string255(cfp + CFP_RELATED_TOPIC, s);
  free(s);
  size_t length;  // a std::string, which may hold NULs: pointer, then size
  uint8_t *bytes = fuzz_sample(in, &length);
  r->expression = malloc(length + 1);
  if (r->expression == NULL) abort();
  memcpy(r->expression, bytes, length);
  r->expression[length] = '\0';
  free(bytes);
  fuzz_put_ptr(cfp + CFP_EXPRESSION, r->expression);
  memcpy(cfp + CFP_EXPRESSION + sizeof(void *), &length, sizeof length);
  r->parameters = calloc((size_t)parameters + 1, STRING255_SIZE);
  if (r->parameters == NULL) abort();
  for (int i = 0; i < parameters; i++) {
    s = fuzz_string(in, NULL);
    fuzz_string255(r->parameters + (size_t)i * STRING255_SIZE, s);
    free(s);
  }
  const uint8_t *end = r->parameters + (size_t)parameters * STRING255_SIZE;
  fuzz_put_ptr(cfp + CFP_PARAMETERS + RLV_VECTOR, r->parameters);
  fuzz_put_ptr(cfp + CFP_PARAMETERS + RLV_VECTOR + sizeof(void *), end);
}

static inline void fuzz_rpd_free(struct fuzz_rpd *r) {
  free(r->buffer);
  free(r->expression);
  free(r->parameters);
}

#endif  // CFT_ACTION_FUZZ_COMMON_H_
