// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The guard's Fast DDS 3 layer hands the guard's C parts Fast DDS 3's identities as bytes, as on
// the wire: a GUID_t as its 12 bytes of prefix and 4 of entity id, a SequenceNumber_t as
// {int32 high, uint32 low} in this machine's order.
#ifndef CFT_ACTION_GUARD_FASTDDS3_BYTES_HPP_
#define CFT_ACTION_GUARD_FASTDDS3_BYTES_HPP_

#include <cstdint>
#include <cstring>

#include <fastdds/rtps/common/Guid.hpp>
#include <fastdds/rtps/common/SequenceNumber.hpp>

namespace cft_action {

inline void guid_bytes(const eprosima::fastdds::rtps::GUID_t &guid, uint8_t out[16]) {
  std::memcpy(out, guid.guidPrefix.value, 12);
  std::memcpy(out + 12, guid.entityId.value, 4);
}

inline void sequence_bytes(const eprosima::fastdds::rtps::SequenceNumber_t &sequence,
                           uint8_t out[8]) {
  std::memcpy(out, &sequence.high, 4);
  std::memcpy(out + 4, &sequence.low, 4);
}

}  // namespace cft_action

#endif  // CFT_ACTION_GUARD_FASTDDS3_BYTES_HPP_
