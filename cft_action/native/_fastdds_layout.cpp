// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The Fast DDS layouts the C parts of cft_action read, measured from the Fast DDS headers this is
// compiled against (docs/INTERNALS.md, section 17). setup.py compiles it to assembly only
// (`c++ -S -fno-access-control`: nothing is linked or run, no Fast DDS code executes) and turns
// the `->NAME VALUE what` lines that the asm statements leave there into _fastdds_layout.h, which
// the guard and the reader's filter class include instead of constants written by hand. This is
// the asm-offsets technique of the Linux kernel. compat/probe.sh prints the same for a stack.
//
// -fno-access-control lets offsetof name the private members; -Wno-invalid-offsetof accepts
// offsetof on classes that are not standard-layout, which GCC and Clang compute like any other.
#include <fastrtps/config.h>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/topic/IContentFilter.hpp>
#include <fastdds/rtps/builtin/data/ReaderProxyData.h>
#include <fastdds/rtps/common/CacheChange.h>
#include <fastdds/rtps/common/SerializedPayload.h>
#include <fastdds/rtps/common/WriteParams.h>
#include <fastdds/rtps/history/ReaderHistory.h>
#include <fastdds/rtps/reader/RTPSReader.h>
#include <fastdds/rtps/reader/StatefulReader.h>
#include <fastdds/rtps/writer/ChangeForReader.h>
#include <fastdds/rtps/writer/StatefulWriter.h>
#include <fastrtps/attributes/TopicAttributes.h>
#include <cstddef>

using eprosima::fastdds::dds::DataWriterQos;
using eprosima::fastdds::dds::IContentFilter;
using eprosima::fastdds::dds::WriterResourceLimitsQos;
using eprosima::fastdds::rtps::ContentFilterProperty;
using eprosima::fastrtps::ResourceLimitedVector;
using eprosima::fastrtps::string_255;
using eprosima::fastrtps::TopicAttributes;
using eprosima::fastrtps::rtps::CacheChange_t;
using eprosima::fastrtps::rtps::ReaderHistory;
using eprosima::fastrtps::rtps::ReaderProxyData;
using eprosima::fastrtps::rtps::ReaderTimes;
using eprosima::fastrtps::rtps::RTPSReader;
using eprosima::fastrtps::rtps::SampleIdentity;
using eprosima::fastrtps::rtps::SequenceNumberSet_t;
using eprosima::fastrtps::rtps::SerializedPayload_t;
using eprosima::fastrtps::rtps::StatefulReader;
using eprosima::fastrtps::rtps::StatefulWriter;
using eprosima::fastrtps::rtps::WriteParams;

#define LAYOUT(name, value, what) asm volatile("\n->" #name " %c0 " what : : "i"((long)(value)))

void cft_fastdds_layout() {
  LAYOUT(CFT_LAYOUT_VERSION_MAJOR, FASTRTPS_VERSION_MAJOR, "Fast DDS version of the headers");
  LAYOUT(CFT_LAYOUT_VERSION_MINOR, FASTRTPS_VERSION_MINOR, "");
  LAYOUT(CFT_LAYOUT_VERSION_MICRO, FASTRTPS_VERSION_MICRO, "");
  LAYOUT(CFT_LAYOUT_HAVE_SECURITY, HAVE_SECURITY, "fastrtps/config.h");
  LAYOUT(RPD_SIZE, sizeof(ReaderProxyData), "sizeof(ReaderProxyData)");
  LAYOUT(RPD_GUID, offsetof(ReaderProxyData, m_guid), "ReaderProxyData::m_guid (GUID_t)");
  LAYOUT(RPD_KEY, offsetof(ReaderProxyData, m_key), "ReaderProxyData::m_key (InstanceHandle_t)");
  LAYOUT(RPD_TYPE_NAME, offsetof(ReaderProxyData, m_typeName), "ReaderProxyData::m_typeName");
  LAYOUT(RPD_TOPIC_NAME, offsetof(ReaderProxyData, m_topicName), "ReaderProxyData::m_topicName");
  LAYOUT(RPD_CONTENT_FILTER, offsetof(ReaderProxyData, content_filter_),
         "ReaderProxyData::content_filter_ (ContentFilterProperty)");
  LAYOUT(CFP_RELATED_TOPIC, offsetof(ContentFilterProperty, related_topic_name),
         "ContentFilterProperty::related_topic_name (string_255)");
  LAYOUT(CFP_CLASS_NAME, offsetof(ContentFilterProperty, filter_class_name),
         "ContentFilterProperty::filter_class_name (string_255)");
  LAYOUT(CFP_EXPRESSION, offsetof(ContentFilterProperty, filter_expression),
         "ContentFilterProperty::filter_expression (std::string)");
  LAYOUT(CFP_PARAMETERS, offsetof(ContentFilterProperty, expression_parameters),
         "ContentFilterProperty::expression_parameters");
  LAYOUT(RLV_VECTOR, offsetof(ResourceLimitedVector<string_255>, collection_),
         "the std::vector inside a ResourceLimitedVector");
  LAYOUT(STRING255_SIZE, sizeof(string_255), "sizeof(fixed_string<255>)");
  LAYOUT(STRING255_LENGTH, offsetof(string_255, string_len), "fixed_string<255>::string_len");
  LAYOUT(PAYLOAD_LENGTH, offsetof(SerializedPayload_t, length), "SerializedPayload_t::length");
  LAYOUT(PAYLOAD_DATA, offsetof(SerializedPayload_t, data), "SerializedPayload_t::data");
  LAYOUT(PAYLOAD_MAX_SIZE, offsetof(SerializedPayload_t, max_size), "SerializedPayload_t::max_size");
  LAYOUT(CC_KIND, offsetof(CacheChange_t, kind), "CacheChange_t::kind (ChangeKind_t)");
  LAYOUT(CC_KIND_SIZE, sizeof(CacheChange_t::kind), "sizeof(ChangeKind_t)");
  LAYOUT(CC_PAYLOAD, offsetof(CacheChange_t, serializedPayload),
         "CacheChange_t::serializedPayload (SerializedPayload_t)");
  LAYOUT(CC_SAMPLE_WRITER_GUID,
         offsetof(CacheChange_t, write_params) + offsetof(WriteParams, sample_identity_) +
             offsetof(SampleIdentity, writer_guid_),
         "CacheChange_t::write_params.sample_identity().writer_guid() (GUID_t)");
  LAYOUT(CC_WRITER_GUID, offsetof(CacheChange_t, writerGUID), "CacheChange_t::writerGUID (GUID_t)");
  LAYOUT(CC_RELATED_WRITER_GUID,
         offsetof(CacheChange_t, write_params) + offsetof(WriteParams, related_sample_identity_) +
             offsetof(SampleIdentity, writer_guid_),
         "CacheChange_t::write_params.related_sample_identity().writer_guid() (GUID_t)");
  LAYOUT(CC_RELATED_SEQUENCE,
         offsetof(CacheChange_t, write_params) + offsetof(WriteParams, related_sample_identity_) +
             offsetof(SampleIdentity, sequence_number_),
         "CacheChange_t::write_params.related_sample_identity().sequence_number()");
  LAYOUT(CC_SEQUENCE, offsetof(CacheChange_t, sequenceNumber),
         "CacheChange_t::sequenceNumber (SequenceNumber_t)");
  LAYOUT(SNS_SIZE, sizeof(SequenceNumberSet_t), "sizeof(SequenceNumberSet_t)");
  LAYOUT(SNS_BASE, offsetof(SequenceNumberSet_t, base_), "SequenceNumberSet_t's base (BitmapRange)");
  LAYOUT(SW_SIZE, sizeof(StatefulWriter), "sizeof(StatefulWriter)");
  LAYOUT(SW_TIMES, offsetof(StatefulWriter, m_times), "StatefulWriter::m_times (WriterTimes)");
  LAYOUT(SW_PERIODIC_HEARTBEAT, offsetof(StatefulWriter, periodic_hb_event_),
         "StatefulWriter::periodic_hb_event_ (TimedEvent*)");
  LAYOUT(WT_SIZE, sizeof(eprosima::fastrtps::rtps::WriterTimes), "sizeof(WriterTimes)");
  LAYOUT(WT_HEARTBEAT_PERIOD, offsetof(eprosima::fastrtps::rtps::WriterTimes, heartbeatPeriod),
         "WriterTimes::heartbeatPeriod (Duration_t)");
  LAYOUT(SW_GUID, offsetof(StatefulWriter, m_guid), "StatefulWriter's Endpoint::m_guid (GUID_t)");
  LAYOUT(SW_SEPARATE_SENDING, offsetof(StatefulWriter, m_separateSendingEnabled),
         "StatefulWriter's RTPSWriter::m_separateSendingEnabled (bool)");
  LAYOUT(FSI_WRITER_GUID,
         offsetof(IContentFilter::FilterSampleInfo, sample_identity) +
             offsetof(SampleIdentity, writer_guid_),
         "IContentFilter::FilterSampleInfo::sample_identity.writer_guid() (GUID_t)");
  LAYOUT(RR_HISTORY, offsetof(RTPSReader, mp_history), "RTPSReader::mp_history");
  LAYOUT(RR_DATA_FILTER, offsetof(RTPSReader, data_filter_), "RTPSReader::data_filter_");
  LAYOUT(RH_READER, offsetof(ReaderHistory, mp_reader), "ReaderHistory::mp_reader");
  LAYOUT(SR_SIZE, sizeof(StatefulReader), "sizeof(StatefulReader)");
  LAYOUT(SR_TIMES, offsetof(StatefulReader, times_), "StatefulReader::times_ (ReaderTimes)");
  LAYOUT(RT_SIZE, sizeof(ReaderTimes), "sizeof(ReaderTimes)");
  LAYOUT(RT_RESPONSE_DELAY, offsetof(ReaderTimes, heartbeatResponseDelay),
         "ReaderTimes::heartbeatResponseDelay (Duration_t)");
  LAYOUT(CFR_UNACKNOWLEDGED, eprosima::fastrtps::rtps::UNACKNOWLEDGED,
         "ChangeForReaderStatus_t UNACKNOWLEDGED (a value)");
  LAYOUT(TOPIC_NAME, offsetof(TopicAttributes, topicName), "TopicAttributes::topicName");
  LAYOUT(DWQ_READER_FILTERS,
         offsetof(DataWriterQos, writer_resource_limits_) +
             offsetof(WriterResourceLimitsQos, reader_filters_allocation),
         "DataWriterQos::writer_resource_limits().reader_filters_allocation");
}
