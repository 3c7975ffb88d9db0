// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's Fast DDS 3 layer: the guard's per-reader decisions, given to a Fast DDS 3.3+
// writer through its public API. It decides nothing itself: which reader gets which sample is the
// family-free parts' (_guard_replies.c's cft_reply_verdict, passed in); this file only carries
// their answer to Fast DDS.
//
// It stands on `DataWriter::set_sample_prefilter(std::shared_ptr<IContentFilter>)` (Fast DDS 3.3+,
// fastdds/dds/publisher/DataWriter.hpp): the writer asks the prefilter, in
// DataWriterImpl::is_relevant, for each change and matched reader (every reader: remote,
// intraprocess, late joiners; no limit of 32 as for content filters), with the change's
// FilterSampleInfo (its sample identity and related sample identity), under the writer's own
// filters mutex. A reader the prefilter refuses gets no DATA: a reliable one a GAP, as for any
// content-filtered change. Nothing is written into the DATA (no filter signature). The prefilter
// is not told a change's kind: a reply topic has no key, so every change of it is ALIVE.
//
// Built by setup.py only against Fast DDS 3.3+ headers, as its own library linked against that Fast
// DDS (libfastdds.so.3.<minor>): its headers' constants have initializers that call into Fast DDS,
// which a library preloaded before Fast DDS is loaded could not run. _guard_endpoints.c dlopens it
// only in a process where that soname is already loaded, so it never loads a Fast DDS of its own.

#include "_prefilter.h"

#include <cstring>
#include <exception>
#include <memory>

#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/topic/IContentFilter.hpp>

namespace {

using eprosima::fastdds::dds::DataWriter;
using eprosima::fastdds::dds::IContentFilter;

void guid_bytes(const eprosima::fastdds::rtps::GUID_t &guid, uint8_t out[16]) {
  std::memcpy(out, guid.guidPrefix.value, 12);
  std::memcpy(out + 12, guid.entityId.value, 4);
}

// An action's reply writer: each reply only to the readers `verdict` does not refuse.
class ReplyRouting final : public IContentFilter {
 public:
  explicit ReplyRouting(cft_reply_verdict_fn verdict) : verdict_(verdict) {}

  bool evaluate(const SerializedPayload & /*payload*/, const FilterSampleInfo &info,
                const GUID_t &reader_guid) const override {
    uint8_t related[16], reader[16];
    guid_bytes(info.related_sample_identity.writer_guid(), related);
    guid_bytes(reader_guid, reader);
    const auto &sequence = info.related_sample_identity.sequence_number();
    return verdict_(related, sequence.high, sequence.low, reader) != 0;
  }

 private:
  const cft_reply_verdict_fn verdict_;
};

}  // namespace

extern "C" __attribute__((visibility("default"))) int32_t cft_fastdds3_route_replies(
    void *datawriter, cft_reply_verdict_fn verdict) {
  try {
    return static_cast<DataWriter *>(datawriter)->set_sample_prefilter(
        std::make_shared<ReplyRouting>(verdict));
  } catch (const std::exception &) {  // no memory for the prefilter: the writer stays as it was
    return 1;                        // RETCODE_ERROR
  }
}
