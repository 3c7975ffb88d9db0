// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The body of a serialized sample, as Fast DDS hands it to a content filter: a SerializedPayload_t
// (public header fastdds/rtps/common/SerializedPayload.h), whose `length` and `data` offsets come
// from the headers the build found (_fastdds_layout.h), or its bytes.
#ifndef CFT_ACTION_CDR_H_
#define CFT_ACTION_CDR_H_

#include <stdbool.h>
#include <stdint.h>
#include <string.h>

#include "_fastdds_layout.h"  // CFT_LAYOUT_KNOWN, PAYLOAD_LENGTH, PAYLOAD_DATA

// The body after the 4-byte encapsulation header of the serialized sample `data` (`length`
// bytes), if it is plain CDR (big endian 0x0000 or little endian 0x0001); else NULL.
// *body_length: its bytes; *little: its byte order. For bytes Fast DDS 3's public API hands over.
static inline const uint8_t *cft_cdr_bytes(const uint8_t *data, uint32_t length,
                                           uint32_t *body_length, bool *little) {
  if (data == NULL || length < 4 || data[0] != 0 || data[1] > 1) return NULL;
  *body_length = length - 4;
  *little = data[1] == 1;
  return data + 4;
}

// cft_cdr_bytes of a SerializedPayload_t. NULL too when the build found no Fast DDS headers to take
// the layout from: then every sample passes, and the Python side decides, as for a plain
// subscription.
static inline const uint8_t *cft_cdr_body(const void *payload, uint32_t *body_length,
                                          bool *little) {
#if CFT_LAYOUT_KNOWN
  const uint8_t *p = payload;
  uint32_t length;
  const uint8_t *data;
  memcpy(&length, p + PAYLOAD_LENGTH, sizeof length);
  memcpy(&data, p + PAYLOAD_DATA, sizeof data);
  return cft_cdr_bytes(data, length, body_length, little);
#else
  (void)payload, (void)body_length, (void)little;
  return NULL;
#endif
}

#endif  // CFT_ACTION_CDR_H_
