// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
// The Fast DDS layout facts the guard depends on, measured from one stack's installed headers.
// Compiled by compat/probe.sh; prints `name value` lines. Only inline accessors of objects that
// are never constructed are used for ReaderProxyData and DataWriterQos (as in tests/test_guard_filter.py
// and tests/test_reader_filter_limit.py), so no Fast DDS code runs for them.
#include <fastrtps/config.h>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/rtps/builtin/data/ReaderProxyData.h>
#include <fastdds/rtps/common/SerializedPayload.h>
#include <cstddef>
#include <cstdio>
#include <cstring>
using namespace eprosima::fastrtps::rtps;
using eprosima::fastdds::dds::DataWriterQos;
using eprosima::fastdds::rtps::ContentFilterProperty;
using eprosima::fastrtps::string_255;
static long diff(const void* a, const void* b) { return (const char*)a - (const char*)b; }
int main() {
  printf("FASTRTPS_VERSION %d.%d.%d\n", FASTRTPS_VERSION_MAJOR, FASTRTPS_VERSION_MINOR,
         FASTRTPS_VERSION_MICRO);
  printf("HAVE_SECURITY %d\n", (int)HAVE_SECURITY);
  printf("HAVE_SQLITE3 %d\n", (int)HAVE_SQLITE3);

  alignas(ReaderProxyData) static char storage[sizeof(ReaderProxyData)];
  auto* rpd = reinterpret_cast<ReaderProxyData*>(storage);
  printf("sizeof(ReaderProxyData) %zu\n", sizeof(ReaderProxyData));
  printf("offsetof(ReaderProxyData::m_guid) %ld\n", diff(&rpd->guid(), rpd));
  printf("offsetof(ReaderProxyData::m_typeName) %ld\n", diff(&rpd->typeName(), rpd));
  printf("sizeof(ReaderProxyData::m_typeName) %zu\n", sizeof(rpd->typeName()));
  printf("offsetof(ReaderProxyData::content_filter_) %ld\n", diff(&rpd->content_filter(), rpd));
  printf("sizeof(ReaderProxyData::content_filter_) %zu\n", sizeof(rpd->content_filter()));
  printf("offsetof(ContentFilterProperty::related_topic_name) %zu\n",
         offsetof(ContentFilterProperty, related_topic_name));
  printf("offsetof(ContentFilterProperty::filter_class_name) %zu\n",
         offsetof(ContentFilterProperty, filter_class_name));
  printf("offsetof(ContentFilterProperty::filter_expression) %zu\n",
         offsetof(ContentFilterProperty, filter_expression));
  printf("offsetof(ContentFilterProperty::expression_parameters) %zu\n",
         offsetof(ContentFilterProperty, expression_parameters));
  printf("sizeof(string_255) %zu\n", sizeof(string_255));
  printf("offsetof(SerializedPayload_t::length) %zu\n", offsetof(SerializedPayload_t, length));
  printf("offsetof(SerializedPayload_t::data) %zu\n", offsetof(SerializedPayload_t, data));

  alignas(DataWriterQos) static char qstorage[sizeof(DataWriterQos)];
  auto* qos = reinterpret_cast<DataWriterQos*>(qstorage);
  const auto& config = qos->writer_resource_limits().reader_filters_allocation;
  printf("sizeof(DataWriterQos) %zu\n", sizeof(DataWriterQos));
  printf("offsetof(DataWriterQos::writer_resource_limits().reader_filters_allocation) %ld\n",
         diff(&config, qstorage));
  printf("sizeof(reader_filters_allocation) %zu\n", sizeof(config));
  return 0;
}
