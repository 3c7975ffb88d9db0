// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The client's Fast DDS 3 layer: how the library's readers ask a guarded Fast DDS 3.3+ writer to
// filter for them (an action client's feedback and status: its own goals' only; a rate-limited or
// polled subscription, a ParameterEventHandler: their program), and learn whether the writers do
// so, through public Fast DDS API.
//
// The client marks its feedback reader: CFT_READER_MARK (native/_filter_class.h, passed in) is
// appended to the reader's USER_DATA with DataReader::set_qos (USER_DATA is changeable; rmw_fastrtps
// put "typehash=...;" there, a key=value; pair as the mark is, which rmw's parser skips), and Fast
// DDS sends the reader's discovery data again. A program's mark (CFT_PROGRAM_READER_MARK) is
// replaced so whenever the program changes (a poll, a new rate). A guarded writer reads the marks
// (native/guard/fastdds3/_prefilter.cpp) and sends the reader only what it asks for; an unguarded
// one ignores USER_DATA. The guarded writer marks its own USER_DATA with CFT_WRITER_MARK, which
// the client reads here from the writers it matches (DataReader::get_matched_publication_data), to
// say where samples are filtered.
//
// Built by setup.py only against Fast DDS 3.3+ headers, as its own library linked against that Fast
// DDS, and loaded by cft_action._rcl only into a process that has that Fast DDS loaded. Called from
// Python threads, outside Fast DDS's callbacks and locks.

#include "_reader_marks.h"

#include "_fastdds3_user_data.hpp"

#include <cstring>
#include <exception>
#include <vector>

#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/rtps/builtin/data/PublicationBuiltinTopicData.hpp>

namespace {

using eprosima::fastdds::dds::DataReader;
using eprosima::fastdds::dds::DataReaderQos;
using eprosima::fastdds::dds::InstanceHandle_t;
using eprosima::fastdds::dds::RETCODE_OK;
using eprosima::fastdds::rtps::GUID_t;

}  // namespace

extern "C" __attribute__((visibility("default"))) int32_t cft_fastdds3_mark_reader(
    void *datareader, const char *mark) {
  try {
    auto *reader = static_cast<DataReader *>(datareader);
    DataReaderQos qos = reader->get_qos();
    return cft_action::append_mark(qos, mark) ? reader->set_qos(qos) : RETCODE_OK;
  } catch (const std::exception &) {  // no memory: the reader stays as it was
    return 1;                         // RETCODE_ERROR
  }
}

extern "C" __attribute__((visibility("default"))) int32_t cft_fastdds3_mark_program(
    void *datareader, const char *prefix, const char *mark) {
  try {
    auto *reader = static_cast<DataReader *>(datareader);
    DataReaderQos qos = reader->get_qos();
    return cft_action::replace_mark(qos, prefix, mark) ? reader->set_qos(qos) : RETCODE_OK;
  } catch (const std::exception &) {  // no memory: the reader stays as it was
    return 1;                         // RETCODE_ERROR
  }
}

extern "C" __attribute__((visibility("default"))) int32_t cft_fastdds3_writer_marked(
    void *datareader, const uint8_t *writer_guid, const char *mark) {
  try {
    GUID_t guid;
    std::memcpy(guid.guidPrefix.value, writer_guid, 12);
    std::memcpy(guid.entityId.value, writer_guid + 12, 4);
    eprosima::fastdds::rtps::PublicationBuiltinTopicData data;
    if (static_cast<DataReader *>(datareader)->get_matched_publication_data(
            data, InstanceHandle_t(guid)) != RETCODE_OK)
      return -1;
    return cft_action::user_data_holds(data.user_data.data_vec(), mark) ? 1 : 0;
  } catch (const std::exception &) {
    return -1;
  }
}

extern "C" __attribute__((visibility("default"))) int32_t cft_fastdds3_marked_writers(
    void *datareader, const char *mark, int32_t *marked) {
  *marked = 0;
  try {
    auto *reader = static_cast<DataReader *>(datareader);
    std::vector<InstanceHandle_t> handles;
    if (reader->get_matched_publications(handles) != RETCODE_OK) return -1;
    int32_t count = 0;
    eprosima::fastdds::rtps::PublicationBuiltinTopicData data;
    for (const InstanceHandle_t &handle : handles) {
      // A writer unmatched meanwhile is not counted.
      if (reader->get_matched_publication_data(data, handle) != RETCODE_OK) continue;
      count++;
      *marked += cft_action::user_data_holds(data.user_data.data_vec(), mark);
    }
    return count;
  } catch (const std::exception &) {
    return -1;
  }
}
