// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// What the guard's _guard_heartbeats.c reads of Fast DDS 3's RTPS types to send a personal GAP in
// its DATA's datagram (part 4 there): answered by the guard's Fast DDS 3 layer (_rtps_types.cpp),
// built with the headers of the Fast DDS it is loaded beside, after dlopen.
#ifndef CFT_ACTION_GUARD_FASTDDS3_RTPS_TYPES_H_
#define CFT_ACTION_GUARD_FASTDDS3_RTPS_TYPES_H_

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define CFT_RTPS_SEQUENCE_SIZE 8  // a SequenceNumber_t: {int32 high, uint32 low}
#define CFT_RTPS_GUID_SIZE 16     // a GUID_t: 12 bytes of prefix, 4 of entity id
#define CFT_RTPS_SET_MAX 64       // room for a SequenceNumberSet_t, copied as bytes

struct cft_rtps_types {
  uint32_t set_size;  // sizeof(SequenceNumberSet_t) (trivially copyable), <= CFT_RTPS_SET_MAX
  // The base of the SequenceNumberSet_t at `set`.
  void (*set_base)(const void *set, uint8_t sequence[CFT_RTPS_SEQUENCE_SIZE]);
  // The sequence number and writer GUID of the CacheChange_t at `change`.
  void (*change_ids)(const void *change, uint8_t sequence[CFT_RTPS_SEQUENCE_SIZE],
                     uint8_t writer_guid[CFT_RTPS_GUID_SIZE]);
  // The GUID of the StatefulWriter at `writer`.
  void (*writer_guid)(const void *writer, uint8_t guid[CFT_RTPS_GUID_SIZE]);
};

#define CFT_FASTDDS3_RTPS_TYPES "cft_fastdds3_rtps_types"
typedef const struct cft_rtps_types *(*cft_fastdds3_rtps_types_fn)(void);

#ifdef __cplusplus
}
#endif

#endif  // CFT_ACTION_GUARD_FASTDDS3_RTPS_TYPES_H_
