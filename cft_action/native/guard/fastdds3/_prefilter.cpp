// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's Fast DDS 3 layer: the guard's per-reader decisions, given to a Fast DDS 3.3+
// writer through its public API. It decides nothing itself: which reader gets which sample is the
// family-free parts' (_guard_replies.c's cft_reply_verdict, _guard_feedback.c's
// cft_feedback_verdict, _guard_status.c's cft_status_judge, _guard_programs.c's cft_program_judge,
// passed in); this file only carries their answer to Fast DDS, and tells the verdicts which readers
// asked for them (their USER_DATA, read outside the prefilter), with each such reader's state.
//
// It stands on `DataWriter::set_sample_prefilter(std::shared_ptr<IContentFilter>)` (Fast DDS 3.3+,
// fastdds/dds/publisher/DataWriter.hpp): the writer asks the prefilter, in
// DataWriterImpl::is_relevant, for each change and matched reader (every reader: remote,
// intraprocess, late joiners; no limit of 32 as for content filters), with the change's
// FilterSampleInfo (its sample identity and related sample identity), under the writer's own
// filters mutex. A reader the prefilter refuses gets no DATA: a reliable one a GAP, as for any
// content-filtered change. Nothing is written into the DATA (no filter signature). The prefilter
// is not told a change's kind: reply and feedback topics have no key, so every change is ALIVE.
//
// Built by setup.py only against Fast DDS 3.3+ headers, as its own library linked against that Fast
// DDS (libfastdds.so.3.<minor>): its headers' constants have initializers that call into Fast DDS,
// which a library preloaded before Fast DDS is loaded could not run. _guard_endpoints.c dlopens it
// only in a process where that soname is already loaded, so it never loads a Fast DDS of its own.

#include "_prefilter.h"

#include "_bytes.hpp"
#include "_fastdds3_user_data.hpp"

#include <atomic>
#include <chrono>
#include <cstring>
#include <exception>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/topic/IContentFilter.hpp>
#include <fastdds/rtps/builtin/data/SubscriptionBuiltinTopicData.hpp>
#include <fastdds/rtps/common/InstanceHandle.hpp>

namespace {

using eprosima::fastdds::dds::DataWriter;
using eprosima::fastdds::dds::DataWriterQos;
using eprosima::fastdds::dds::Duration_t;
using eprosima::fastdds::dds::IContentFilter;
using eprosima::fastdds::dds::InstanceHandle_t;
using eprosima::fastdds::dds::RETCODE_OK;
using eprosima::fastdds::rtps::GUID_t;
using eprosima::fastdds::rtps::SubscriptionBuiltinTopicData;
using cft_action::guid_bytes;
using Clock = std::chrono::steady_clock;

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

// An action's feedback or status writer, or any writer whose readers mark a program: each sample
// to every reader, except that a reader whose discovery data carries the reader mark gets only what
// the verdict does not refuse, judged with that reader's state. Which readers carry it is learnt
// outside the prefilter (readers()), never inside it: evaluate runs under the writer's mutex, and
// DataWriter::get_matched_subscription_data takes the participant's discovery lock, which the
// discovery thread holds when it takes writers' mutexes. A reader not known yet passes.
class MarkedRouting final : public IContentFilter {
 public:
  MarkedRouting(const cft_marked_verdict *verdict, const char *reader_mark)
      : verdict_(*verdict), mark_(reader_mark) {}

  ~MarkedRouting() override {
    for (auto &known : readers_) forget(known.second);
  }

  bool evaluate(const SerializedPayload &payload, const FilterSampleInfo & /*info*/,
                const GUID_t &reader_guid) const override {
    std::lock_guard<std::mutex> lock(mutex_);
    auto found = readers_.find(reader_guid);
    if (found == readers_.end() || !found->second.judged) {
      if (verdict_.unjudged != nullptr) verdict_.unjudged();
      return true;
    }
    uint8_t reader[16];
    guid_bytes(reader_guid, reader);
    return verdict_.judge(&found->second.state, payload.data, payload.length, reader) != 0;
  }

  // The readers `writer` matches, each marked or not; only those new since the last call are
  // looked up (and, with the verdict's update, the marked ones), unless every one is due again.
  // Returns how many are judged. At nearly every write nothing changed: then the knowledge is only
  // compared (or, with the verdict's lookup_ms, not even that until it is due).
  // One caller at a time (a writer may publish from several threads); another meanwhile returns
  // -1 at once: the running one brings the knowledge up to date.
  int32_t readers(DataWriter &writer) {
    std::unique_lock<std::mutex> reading(reading_, std::try_to_lock);
    if (!reading.owns_lock()) return -1;
    Clock::time_point now = Clock::now();
    if (verdict_.lookup_ms > 0) {
      if (now - looked_at_ < std::chrono::milliseconds(verdict_.lookup_ms)) return judged_count_;
      looked_at_ = now;
    }
    if (writer.get_matched_subscriptions(handles_) != RETCODE_OK) return -1;
    bool all = now - read_at_ >= std::chrono::milliseconds(CFT_FASTDDS3_REREAD_MS);
    std::map<GUID_t, Mark> known;  // the marks known now
    {
      std::lock_guard<std::mutex> lock(mutex_);
      // A program changes with its mark (a poll): with update, marked readers are read each look.
      if (!all && knows_all() && (verdict_.update == nullptr || judged_count_ == 0))
        return judged_count_;
      for (const auto &reader : readers_) known.emplace(reader.first, reader.second.mark);
    }
    std::map<GUID_t, Mark> fresh;
    SubscriptionBuiltinTopicData data;
    for (const InstanceHandle_t &handle : handles_) {
      GUID_t guid = eprosima::fastdds::rtps::iHandle2GUID(handle);
      auto found = known.find(guid);
      bool again = found != known.end() && verdict_.update != nullptr && found->second.present;
      if (!all && found != known.end() && !again) {
        fresh.emplace(guid, found->second);
      } else if (writer.get_matched_subscription_data(data, handle) == RETCODE_OK) {
        fresh.emplace(guid, mark_of(data.user_data.data_vec()));
      }  // else: unmatched meanwhile, or not known to discovery: not known (passes)
    }
    if (all) read_at_ = now;
    // The states move over (the verdict may have replaced one meanwhile: they are taken now).
    std::map<GUID_t, Reader> next;
    int32_t count = 0;
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto &mark : fresh) {
      Reader &reader = next[mark.first];
      reader.mark = mark.second;
      if (!reader.mark.present) continue;
      auto before = readers_.find(mark.first);
      bool had = before != readers_.end() && before->second.mark.present;
      if (had) std::swap(reader.state, before->second.state);
      if (verdict_.update == nullptr)
        reader.judged = true;
      else if (had && before->second.mark.value == reader.mark.value)
        reader.judged = before->second.judged;
      else
        reader.judged = verdict_.update(&reader.state, reader.mark.value.data(),
                                        static_cast<uint32_t>(reader.mark.value.size())) != 0;
      count += reader.judged;
    }
    for (auto &gone : readers_) forget(gone.second);
    readers_.swap(next);
    judged_count_ = count;
    return count;
  }

 private:
  struct Mark {
    bool present = false;
    std::string value;  // the program, for a verdict with update
  };
  struct Reader {
    Mark mark;
    bool judged = false;    // its samples are judged: marked, and its program (if any) taken
    void *state = nullptr;  // the verdict's, for a marked reader
  };

  Mark mark_of(const std::vector<eprosima::fastdds::rtps::octet> &user_data) const {
    Mark mark;
    if (verdict_.update == nullptr)
      mark.present = cft_action::user_data_holds(user_data, mark_.c_str());
    else
      mark.present = cft_action::user_data_value(user_data, mark_.c_str(), &mark.value);
    return mark;
  }

  void forget(Reader &reader) const {
    if (reader.state != nullptr && verdict_.forget != nullptr) verdict_.forget(reader.state);
    reader.state = nullptr;
  }

  // Whether the knowledge holds exactly the readers of handles_ (under mutex_ and reading_).
  bool knows_all() const {
    if (handles_.size() != readers_.size()) return false;
    for (const InstanceHandle_t &handle : handles_)
      if (readers_.count(eprosima::fastdds::rtps::iHandle2GUID(handle)) == 0) return false;
    return true;
  }

  const cft_marked_verdict verdict_;
  const std::string mark_;
  mutable std::mutex mutex_;                 // held by each verdict
  mutable std::map<GUID_t, Reader> readers_;  // under mutex_
  std::atomic<int32_t> judged_count_{0};     // readers_'s judged readers
  std::mutex reading_;                       // held by readers()
  std::vector<InstanceHandle_t> handles_;    // the last reading's (under reading_)
  Clock::time_point read_at_;                // the readers' last full reading (under reading_)
  Clock::time_point looked_at_;              // the last look, with lookup_ms (under reading_)
};

// Whether a reliable writer's `qos` had a heartbeat period longer than `ms` (> 0), now `ms`.
bool shorten_heartbeat(DataWriterQos &qos, int32_t ms) {
  if (ms <= 0 || qos.reliability().kind != eprosima::fastdds::dds::RELIABLE_RELIABILITY_QOS)
    return false;
  Duration_t &period = qos.reliable_writer_qos().times.heartbeat_period;
  Duration_t wanted(ms / 1000, static_cast<uint32_t>(ms % 1000) * 1000000u);
  if (!(wanted < period)) return false;
  period = wanted;
  return true;
}

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

// The handle is a MarkedRouting that the writer shares (its prefilter): it lives as long as the
// guard keeps the handle (until its publisher is destroyed: cft_fastdds3_release) or the writer
// keeps the prefilter.
extern "C" __attribute__((visibility("default"))) void *cft_fastdds3_route_marked(
    void *datawriter, const cft_marked_verdict *verdict, const char *reader_mark,
    const char *writer_mark, int32_t *heartbeat_ms, int32_t *error) {
  auto *writer = static_cast<DataWriter *>(datawriter);
  try {
    auto routing = std::make_shared<MarkedRouting>(verdict, reader_mark);
    *error = writer->set_sample_prefilter(routing);
    if (*error != RETCODE_OK) return nullptr;
    DataWriterQos qos = writer->get_qos();
    bool marked = cft_action::append_mark(qos, writer_mark);
    bool shorter = shorten_heartbeat(qos, *heartbeat_ms);
    if ((marked || shorter) && (*error = writer->set_qos(qos)) != RETCODE_OK) {
      writer->set_sample_prefilter(nullptr);
      return nullptr;
    }
    if (!shorter) *heartbeat_ms = 0;
    return new std::shared_ptr<MarkedRouting>(routing);
  } catch (const std::exception &) {  // no memory: the writer stays as it was
    *error = 1;                       // RETCODE_ERROR
    return nullptr;
  }
}

extern "C" __attribute__((visibility("default"))) int32_t cft_fastdds3_marked_readers(
    void *handle, void *datawriter) {
  try {
    return (*static_cast<std::shared_ptr<MarkedRouting> *>(handle))->readers(
        *static_cast<DataWriter *>(datawriter));
  } catch (const std::exception &) {  // no memory: what was known stays
    return -1;
  }
}

extern "C" __attribute__((visibility("default"))) void cft_fastdds3_release(void *handle) {
  delete static_cast<std::shared_ptr<MarkedRouting> *>(handle);
}
