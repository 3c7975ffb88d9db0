// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The library's marks in a Fast DDS 3 endpoint's USER_DATA (public API), for both Fast DDS 3 layers
// (guard/fastdds3/, reader/fastdds3/): a mark is a "key=value;" pair (native/_filter_class.h),
// appended after rmw_fastrtps's "typehash=...;", which rmw's parser skips.
#ifndef CFT_ACTION_FASTDDS3_USER_DATA_HPP_
#define CFT_ACTION_FASTDDS3_USER_DATA_HPP_

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include <fastdds/rtps/common/Types.hpp>

namespace cft_action {

// Whether `data` (an endpoint's USER_DATA) holds `mark`.
inline bool user_data_holds(const std::vector<eprosima::fastdds::rtps::octet> &data,
                            const char *mark) {
  const char *end = mark + std::strlen(mark);
  return mark != end && std::search(data.begin(), data.end(), mark, end) != data.end();
}

// Whether `data` holds a mark that starts with `prefix`; then *value is the rest of the mark, up to
// its ';' (or the end of `data`).
inline bool user_data_value(const std::vector<eprosima::fastdds::rtps::octet> &data,
                            const char *prefix, std::string *value) {
  const char *end = prefix + std::strlen(prefix);
  auto at = std::search(data.begin(), data.end(), prefix, end);
  if (prefix == end || at == data.end()) return false;
  at += end - prefix;
  value->assign(at, std::find(at, data.end(), ';'));
  return true;
}

// `data` with `mark` appended, as the USER_DATA of `qos` (a DataWriterQos or DataReaderQos).
template <typename Qos>
void store_with_mark(Qos &qos, std::vector<eprosima::fastdds::rtps::octet> &data,
                     const char *mark) {
  data.insert(data.end(), mark, mark + std::strlen(mark));
  qos.user_data().resize(data.size());  // as rmw_fastrtps sets it
  qos.user_data().setValue(data);
}

// `mark` appended to the USER_DATA of `qos`, unless it holds it already: whether it changed (then
// the caller sets the QoS).
template <typename Qos>
bool append_mark(Qos &qos, const char *mark) {
  std::vector<eprosima::fastdds::rtps::octet> data = qos.user_data().data_vec();
  if (user_data_holds(data, mark)) return false;
  store_with_mark(qos, data, mark);
  return true;
}

// The mark that starts with `prefix` in the USER_DATA of `qos` (a DataReaderQos) made `mark`
// (which starts with it and ends with ';'), appended if there was none: whether it changed.
template <typename Qos>
bool replace_mark(Qos &qos, const char *prefix, const char *mark) {
  std::vector<eprosima::fastdds::rtps::octet> data = qos.user_data().data_vec();
  const char *prefix_end = prefix + std::strlen(prefix);
  auto at = std::search(data.begin(), data.end(), prefix, prefix_end);
  if (at != data.end()) {
    auto end = std::find(at, data.end(), ';');
    if (end != data.end()) ++end;
    if (std::equal(at, end, mark, mark + std::strlen(mark))) return false;
    data.erase(at, end);
  }
  store_with_mark(qos, data, mark);
  return true;
}

}  // namespace cft_action

#endif  // CFT_ACTION_FASTDDS3_USER_DATA_HPP_
