// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The library's marks in a Fast DDS 3 endpoint's USER_DATA (public API), for both Fast DDS 3 layers
// (guard/fastdds3/, reader/fastdds3/): a mark is a "key=value;" pair (native/_filter_class.h),
// appended after rmw_fastrtps's "typehash=...;", which rmw's parser skips.
#ifndef CFT_ACTION_FASTDDS3_USER_DATA_HPP_
#define CFT_ACTION_FASTDDS3_USER_DATA_HPP_

#include <algorithm>
#include <cstring>
#include <vector>

#include <fastdds/rtps/common/Types.hpp>

namespace cft_action {

// Whether `data` (an endpoint's USER_DATA) holds `mark`.
inline bool user_data_holds(const std::vector<eprosima::fastdds::rtps::octet> &data,
                            const char *mark) {
  const char *end = mark + std::strlen(mark);
  return mark != end && std::search(data.begin(), data.end(), mark, end) != data.end();
}

// `mark` appended to the USER_DATA of `qos` (a DataWriterQos or DataReaderQos), unless it holds it
// already: whether it changed (then the caller sets the QoS).
template <typename Qos>
bool append_mark(Qos &qos, const char *mark) {
  std::vector<eprosima::fastdds::rtps::octet> data = qos.user_data().data_vec();
  if (user_data_holds(data, mark)) return false;
  data.insert(data.end(), mark, mark + std::strlen(mark));
  qos.user_data().resize(data.size());  // as rmw_fastrtps sets it
  qos.user_data().setValue(data);
  return true;
}

}  // namespace cft_action

#endif  // CFT_ACTION_FASTDDS3_USER_DATA_HPP_
