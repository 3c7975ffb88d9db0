// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The guard's Fast DDS 3 layer: what _guard_heartbeats.c reads of a change, a sequence number set
// and a writer (_rtps_types.h), through the public headers of the Fast DDS this layer was built
// with (CacheChange_t, SequenceNumberSet_t, RTPSWriter: fastdds/rtps/). The writer that calls
// _guard_heartbeats.c's members is a StatefulWriter, whose first base is BaseWriter and its first
// RTPSWriter (v3.6.2: src/cpp/rtps/writer/StatefulWriter.hpp, BaseWriter.hpp), so that its address
// is its RTPSWriter's; _guard_heartbeats.c checks each GUID read so against the writer GUID of the
// DATA it merges into, and stops merging at the first that differs.

#include "_rtps_types.h"

#include <type_traits>

#include "_bytes.hpp"

#include <fastdds/rtps/common/CacheChange.hpp>
#include <fastdds/rtps/common/SequenceNumber.hpp>
#include <fastdds/rtps/writer/RTPSWriter.hpp>

namespace {

using eprosima::fastdds::rtps::CacheChange_t;
using eprosima::fastdds::rtps::RTPSWriter;
using eprosima::fastdds::rtps::SequenceNumberSet_t;

using cft_action::guid_bytes;
using cft_action::sequence_bytes;

static_assert(std::is_trivially_copyable<SequenceNumberSet_t>::value &&
                  sizeof(SequenceNumberSet_t) <= CFT_RTPS_SET_MAX,
              "_guard_heartbeats.c copies a SequenceNumberSet_t as CFT_RTPS_SET_MAX bytes at most");

void set_base(const void *set, uint8_t sequence[CFT_RTPS_SEQUENCE_SIZE]) {
  sequence_bytes(static_cast<const SequenceNumberSet_t *>(set)->base(), sequence);
}

void change_ids(const void *change, uint8_t sequence[CFT_RTPS_SEQUENCE_SIZE],
                uint8_t writer_guid[CFT_RTPS_GUID_SIZE]) {
  const auto *c = static_cast<const CacheChange_t *>(change);
  sequence_bytes(c->sequenceNumber, sequence);
  guid_bytes(c->writerGUID, writer_guid);
}

void writer_guid(const void *writer, uint8_t guid[CFT_RTPS_GUID_SIZE]) {
  guid_bytes(static_cast<const RTPSWriter *>(writer)->getGuid(), guid);
}

const cft_rtps_types types = {sizeof(SequenceNumberSet_t), set_base, change_ids, writer_guid};

}  // namespace

extern "C" __attribute__((visibility("default"))) const cft_rtps_types *cft_fastdds3_rtps_types() {
  return &types;
}
