// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// A hostile participant for tests/test_hostile.py: a plain Fast DDS participant (no ROS, no
// cft_action) that announces content-filtered readers with whatever filter class, expression and
// parameters it is told, as any participant on the domain can. Each filter class other than DDSSQL
// gets a factory here that accepts every expression and passes every sample, so that Fast DDS
// announces the filter as given (bytes that are not UTF-8, embedded NULs, 100 parameters, an
// expression of 64 kB). DDSSQL is Fast DDS's own factory, which compiles only for a type with a
// TypeObject: a DDSSQL reader is created with a class of this file's (AS_DDSSQL), whose name is
// replaced by DDSSQL in the announcement, where RTPSParticipant::registerReader (called through
// libfastrtps's PLT, and defined here) receives the reader's filter property.
// Its samples are taken as raw bytes under the type name given, so it matches ROS writers by type
// name and counts what it receives, per goal UUID (the 16 bytes after the 4-byte CDR header).
//
// Discovery as rmw_fastrtps's participants with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST: no
// multicast metatraffic locator, 127.0.0.1 as the initial peer; domain ROS_DOMAIN_ID.
//
// Commands on stdin, one a line; strings in hex ("-" for an empty one):
//   spec SPEC TOPIC TYPE CLASS EXPRESSION [PARAMETER ...]  defines a reader (TOPIC, TYPE plain;
//                           CLASS "-": a reader without a filter, as a plain reader)
//   open SPEC READER [P]    creates it, in the participant P (started on first use; without P,
//                           the first one): OPENED READER ok|failed
//   close READER            deletes it: CLOSED READER
//   churn COUNT WINDOW MS PREFIX  creates COUNT readers, the specs whose name starts with PREFIX
//                           in turn, one every MS milliseconds, at most WINDOW alive (the oldest
//                           deleted first), then deletes the rest: CHURNED <count> <failed to open>
//   count READER            COUNT READER <matched writers> <samples> {"<uuid hex>": n, ...}
// It prints READY once its first participant is up, and leaves at the end of its input.
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/ContentFilteredTopic.hpp>
#include <fastdds/dds/topic/IContentFilterFactory.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/builtin/data/ContentFilterProperty.hpp>
#include <fastrtps/utils/IPLocator.h>

#include <dlfcn.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

using namespace eprosima::fastdds::dds;
using eprosima::fastrtps::rtps::SerializedPayload_t;

#define REGISTER_READER                                                                      \
  "_ZN8eprosima8fastrtps4rtps15RTPSParticipant14registerReaderEPNS1_10RTPSReaderERKNS0_15" \
  "TopicAttributesERKNS_7fastdds3dds9ReaderQosEPKNS8_4rtps21ContentFilterPropertyE"
#define AS_DDSSQL "CFT_HOSTILE_AS_DDSSQL"

// RTPSParticipant::registerReader, before the reader is announced: AS_DDSSQL becomes DDSSQL.
extern "C" __attribute__((visibility("default"))) bool hostile_register_reader(
    void* self, void* reader, const void* topic, const void* qos,
    const eprosima::fastdds::rtps::ContentFilterProperty* filter) __asm__(REGISTER_READER);
bool hostile_register_reader(void* self, void* reader, const void* topic, const void* qos,
                             const eprosima::fastdds::rtps::ContentFilterProperty* filter) {
  using real_fn = bool (*)(void*, void*, const void*, const void*, const void*);
  static real_fn real = reinterpret_cast<real_fn>(dlsym(RTLD_NEXT, REGISTER_READER));
  if (filter != nullptr && strcmp(filter->filter_class_name.c_str(), AS_DDSSQL) == 0)
    const_cast<eprosima::fastdds::rtps::ContentFilterProperty*>(filter)->filter_class_name =
        "DDSSQL";
  return real(self, reader, topic, qos, filter);
}

namespace {

struct Raw {
  std::vector<unsigned char> bytes;
};

// Any type name, its samples as raw bytes.
class RawType : public TopicDataType {
 public:
  explicit RawType(const std::string& name) {
    setName(name.c_str());
    m_typeSize = 4096;
    m_isGetKeyDefined = false;
    auto_fill_type_object(false);
    auto_fill_type_information(false);
  }
  bool serialize(void* data, SerializedPayload_t* payload) override {
    const Raw* raw = static_cast<Raw*>(data);
    if (raw->bytes.size() > payload->max_size) return false;
    memcpy(payload->data, raw->bytes.data(), raw->bytes.size());
    payload->length = static_cast<uint32_t>(raw->bytes.size());
    return true;
  }
  bool deserialize(SerializedPayload_t* payload, void* data) override {
    static_cast<Raw*>(data)->bytes.assign(payload->data, payload->data + payload->length);
    return true;
  }
  std::function<uint32_t()> getSerializedSizeProvider(void* data) override {
    return [data] { return static_cast<uint32_t>(static_cast<Raw*>(data)->bytes.size()); };
  }
  void* createData() override { return new Raw(); }
  void deleteData(void* data) override { delete static_cast<Raw*>(data); }
  bool getKey(void*, eprosima::fastrtps::rtps::InstanceHandle_t*, bool) override { return false; }
};

class PassAll : public IContentFilter {
 public:
  bool evaluate(const SerializedPayload&, const FilterSampleInfo&, const GUID_t&) const override {
    return true;
  }
};

class PassAllFactory : public IContentFilterFactory {
 public:
  ReturnCode_t create_content_filter(const char*, const char*, const TopicDataType*, const char*,
                                     const ParameterSeq&, IContentFilter*& instance) override {
    instance = &filter_;
    return ReturnCode_t::RETCODE_OK;
  }
  ReturnCode_t delete_content_filter(const char*, IContentFilter*) override {
    return ReturnCode_t::RETCODE_OK;
  }

 private:
  PassAll filter_;
};

struct Spec {
  std::string topic, type, filter_class, expression;
  std::vector<std::string> parameters;
};

// What one reader received: samples, per goal UUID.
class Counter : public DataReaderListener {
 public:
  void on_data_available(DataReader* reader) override {
    Raw raw;
    SampleInfo info;
    while (reader->take_next_sample(&raw, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      std::lock_guard<std::mutex> lock(mutex_);
      samples_++;
      if (raw.bytes.size() >= 20) {
        char hex[33];
        for (int i = 0; i < 16; i++) snprintf(hex + 2 * i, 3, "%02x", raw.bytes[4 + i]);
        per_uuid_[hex]++;
      }
    }
  }
  void on_subscription_matched(DataReader*, const SubscriptionMatchedStatus& status) override {
    std::lock_guard<std::mutex> lock(mutex_);
    matched_ = status.current_count;
  }
  std::string report() {
    std::lock_guard<std::mutex> lock(mutex_);
    std::ostringstream out;
    out << matched_ << ' ' << samples_ << " {";
    const char* sep = "";
    for (const auto& [uuid, n] : per_uuid_) {
      out << sep << '"' << uuid << "\": " << n;
      sep = ", ";
    }
    out << '}';
    return out.str();
  }

 private:
  std::mutex mutex_;
  int matched_ = 0;
  unsigned long samples_ = 0;
  std::map<std::string, unsigned long> per_uuid_;
};

class Participant;
struct Reader {
  Participant* in = nullptr;
  ContentFilteredTopic* topic = nullptr;
  DataReader* reader = nullptr;
  std::unique_ptr<Counter> counter;
};

std::string unhex(const std::string& text) {
  std::string out;
  if (text == "-") return out;
  for (size_t i = 0; i + 1 < text.size(); i += 2)
    out.push_back(static_cast<char>(std::stoi(text.substr(i, 2), nullptr, 16)));
  return out;
}

// A participant of its own: its subscriber, topics and content filter factory.
class Participant {
 public:
  bool start() {
    DomainParticipantQos qos = PARTICIPANT_QOS_DEFAULT;
    auto& builtin = qos.wire_protocol().builtin;
    builtin.metatrafficMulticastLocatorList.clear();
    builtin.metatrafficUnicastLocatorList.push_back(eprosima::fastrtps::rtps::Locator_t());
    eprosima::fastrtps::rtps::Locator_t peer;
    eprosima::fastrtps::rtps::IPLocator::setIPv4(peer, "127.0.0.1");
    builtin.initialPeersList.push_back(peer);
    qos.name("cft_hostile");
    const char* domain = getenv("ROS_DOMAIN_ID");
    participant_ = DomainParticipantFactory::get_instance()->create_participant(
        domain != nullptr ? atoi(domain) : 0, qos);
    if (participant_ == nullptr) return false;
    subscriber_ = participant_->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
    return subscriber_ != nullptr;
  }

  bool open(const Spec& s, const std::string& id, Reader& r) {
    Topic* topic = topic_for(s);
    if (topic == nullptr) return false;
    if (!s.filter_class.empty()) {
      const char* filter_class = s.filter_class == "DDSSQL" ? AS_DDSSQL : s.filter_class.c_str();
      // PRECONDITION_NOT_MET when registered already.
      participant_->register_content_filter_factory(filter_class, &factory_);
      r.topic = participant_->create_contentfilteredtopic("cft_hostile_" + id, topic,
                                                          s.expression, s.parameters, filter_class);
      if (r.topic == nullptr) return false;
    }
    DataReaderQos qos = DATAREADER_QOS_DEFAULT;
    qos.reliability().kind = RELIABLE_RELIABILITY_QOS;
    qos.history().kind = KEEP_LAST_HISTORY_QOS;
    qos.history().depth = 100;
    qos.endpoint().history_memory_policy =
        eprosima::fastrtps::rtps::DYNAMIC_REUSABLE_MEMORY_MODE;
    r.counter = std::make_unique<Counter>();
    r.reader = subscriber_->create_datareader(
        r.topic != nullptr ? static_cast<TopicDescription*>(r.topic) : topic, qos, r.counter.get());
    if (r.reader == nullptr) {
      if (r.topic != nullptr) participant_->delete_contentfilteredtopic(r.topic);
      return false;
    }
    return true;
  }

  void close(Reader& r) {
    subscriber_->delete_datareader(r.reader);
    if (r.topic != nullptr) participant_->delete_contentfilteredtopic(r.topic);
  }

  void stop() {
    if (participant_ == nullptr) return;
    participant_->delete_contained_entities();
    DomainParticipantFactory::get_instance()->delete_participant(participant_);
  }

 private:
  Topic* topic_for(const Spec& s) {
    auto found = topics_.find(s.topic);
    if (found != topics_.end()) return found->second;
    TypeSupport type(new RawType(s.type));
    if (type.register_type(participant_) != ReturnCode_t::RETCODE_OK) return nullptr;
    Topic* topic = participant_->create_topic(s.topic, s.type, TOPIC_QOS_DEFAULT);
    if (topic != nullptr) topics_[s.topic] = topic;
    return topic;
  }

  DomainParticipant* participant_ = nullptr;
  Subscriber* subscriber_ = nullptr;
  PassAllFactory factory_;
  std::map<std::string, Topic*> topics_;
};

class Hostile {
 public:
  bool start() { return participant("").start(); }

  void spec(const std::string& id, Spec spec) { specs_[id] = std::move(spec); }

  // In the participant named `in` ("" the first one), started on first use.
  bool open(const std::string& spec_id, const std::string& id, const std::string& in = "") {
    auto found = specs_.find(spec_id);
    if (found == specs_.end() || readers_.count(id) != 0) return false;
    bool fresh = participants_.count(in) == 0;
    Participant& p = participant(in);
    if (fresh && !p.start()) return false;
    Reader r;
    r.in = &p;
    if (!p.open(found->second, id, r)) return false;
    readers_[id] = std::move(r);
    return true;
  }

  void close(const std::string& id) {
    auto found = readers_.find(id);
    if (found == readers_.end()) return;
    found->second.in->close(found->second);
    readers_.erase(found);
  }

  // COUNT readers, the specs in turn, one every `pause`, at most WINDOW alive; returns how many
  // failed to open.
  int churn(int count, size_t window, std::chrono::milliseconds pause, const std::string& prefix) {
    std::vector<std::string> chosen;
    for (const auto& [name, spec] : specs_)
      if (name.compare(0, prefix.size(), prefix) == 0) chosen.push_back(name);
    std::deque<std::string> alive;
    int failed = chosen.empty() ? count : 0;
    for (int i = 0; i < count && !chosen.empty(); i++) {
      std::string id = "churn" + std::to_string(churned_++);
      if (open(chosen[i % chosen.size()], id)) alive.push_back(id);
      else failed++;
      while (alive.size() > window) {
        close(alive.front());
        alive.pop_front();
      }
      std::this_thread::sleep_for(pause);
    }
    for (const auto& id : alive) close(id);
    return failed;
  }

  std::string report(const std::string& id) {
    auto found = readers_.find(id);
    return found == readers_.end() ? "0 0 {}" : found->second.counter->report();
  }

  void stop() {
    for (auto& [id, r] : readers_) r.in->close(r);
    readers_.clear();
    for (auto& [name, p] : participants_) p.stop();
  }

 private:
  Participant& participant(const std::string& name) { return participants_[name]; }

  std::map<std::string, Spec> specs_;
  std::map<std::string, Participant> participants_;
  std::map<std::string, Reader> readers_;
  unsigned long churned_ = 0;
};

}  // namespace

int main() {
  Hostile hostile;
  if (!hostile.start()) {
    std::cout << "FAILED participant" << std::endl;
    return 1;
  }
  std::cout << "READY" << std::endl;
  std::string line;
  while (std::getline(std::cin, line)) {
    std::istringstream in(line);
    std::string command;
    in >> command;
    if (command == "spec") {
      std::string id, topic, type, filter_class, expression, parameter;
      in >> id >> topic >> type >> filter_class >> expression;
      Spec s{topic, type, unhex(filter_class), unhex(expression), {}};
      while (in >> parameter) s.parameters.push_back(unhex(parameter));
      hostile.spec(id, std::move(s));
    } else if (command == "open") {
      std::string spec, id, participant;
      in >> spec >> id >> participant;
      std::cout << "OPENED " << id << (hostile.open(spec, id, participant) ? " ok" : " failed")
                << std::endl;
    } else if (command == "close") {
      std::string id;
      in >> id;
      hostile.close(id);
      std::cout << "CLOSED " << id << std::endl;
    } else if (command == "churn") {
      int count = 0, pause = 0;
      size_t window = 1;
      std::string prefix;
      in >> count >> window >> pause >> prefix;
      int failed = hostile.churn(count, window, std::chrono::milliseconds(pause), prefix);
      std::cout << "CHURNED " << count << ' ' << failed << std::endl;
    } else if (command == "count") {
      std::string id;
      in >> id;
      std::cout << "COUNT " << id << ' ' << hostile.report(id) << std::endl;
    }
  }
  hostile.stop();
  return 0;
}
