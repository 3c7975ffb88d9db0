// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's fifth part: an action server's goal, cancel and result replies go only to
// the response readers of the participant that sent the request.
//
// rmw_fastrtps answers a request by writing the reply on the service's one response writer
// (`rr/<service>Reply`), which sends it to every client's response reader; each client's take then
// discards the replies whose related sample identity names neither its response reader nor its
// request writer (`__rmw_take_response`), after they crossed the network. A result of R bytes thus
// reaches every client of the action: N clients pay N x R (docs/INTERNALS.md, section 23, has the
// client side: each client's response readers drop the others' replies on arrival).
//
// Where the guard decides. `__rmw_send_response` puts the request's identity (the client's response
// reader GUID, or its request writer's, and the request's sequence number) into the write's
// `WriteParams::related_sample_identity`, and `WriterHistory::prepare_and_add_change` copies those
// parameters into the change (`CacheChange_t::write_params`) before the RTPS writer is told of it.
// Every DataWriterImpl whose liveliness lease is infinite (rmw's services: the default) is its RTPS
// writer's IReaderDataFilter, so the writer asks DataWriterImpl::is_relevant, per change and matched
// reader (ReaderProxy::rtps_is_relevant: when the change is added, for late joiners, and, for best
// effort, at each send). _guard.c interposes that member; for a change of a reply writer with a
// known related identity this file answers "not relevant" to every reader whose GUID prefix is not
// the identity's, i.e. to the readers of other participants, whose take would discard the reply.
// The RTPS writer then sends those readers no DATA: a reliable one gets a GAP for it with its next
// sample, NACK or periodic heartbeat, as for any filtered-out change, and never stalls. A reader
// of the requesting participant, and every reader of a reply without an identity, gets what Fast
// DDS decides (everything: no reply writer has a filtered reader). Nothing is written into the
// change: no inline QoS, no filter signature, for any reader.
//
// Which writers are reply writers. _guard.c calls cft_replies_reader_matched after the real
// process_reader_filter_info, which Fast DDS calls for every reader a writer matches (not for
// intraprocess ones). The reader's topic name comes from its discovery data, through the layout
// _guard_filter.c checks (cft_filter_reader_topic); a reader matched the writer, so it is the
// writer's topic. A writer of an action's `rr/.../_action/{send_goal,cancel_goal,get_result}Reply`
// is marked under its GUID (DataWriterImpl::guid(), exported), and a change is looked up under its
// own writerGUID: GUIDs are not reused, so a mark never applies to another writer. Requests this
// process writes carry an identity too (rmw's `rq/` writers), but their writers are never marked.
//
// Fast DDS 3.3+ (Lyrical) asks the same decision, cft_reply_verdict, through public API:
// _guard_endpoints.c gives an action's response writers, when rcl creates their services, the
// sample prefilter of fastdds3/_prefilter.cpp, which Fast DDS asks per reply and reader with the
// change's related sample identity (every reader, without marks, CacheChange_t or reader data).
//
// Soundness rules:
// - Fast DDS 2.14: only where _guard.c locks the Fast DDS 2.14 it knows, with a layout from its
//   headers. Fast DDS 3: only with the layer's conditions (_guard_endpoints.c).
// - Only ALIVE changes, and only an identity that reads as rmw writes it: a user entity (writer
//   kind 0x02/0x03, reader kind 0x04/0x07) and a positive sequence number; anything else is
//   counted (`implausible`) and sent as Fast DDS sends it.
// - A full mark table leaves the writer unmarked (`full`): its replies go to everyone, as before.
// - A data-sharing reader is judged like any other. rmw_fastrtps turns data sharing off for its
//   service writers unless its XML QoS is used (leave_middleware_default_qos); that case is not
//   tested.
// - CFT_GUARD_REPLIES=off (or 0) turns this file off, on both families.

#define _GNU_SOURCE
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "_fastdds_layout.h"
#include "_guard_families.h"
#include "_guard_filter.h"
#include "_guard_log.h"
#include "_guard_replies.h"
#include "_guard_text.h"

#define FASTDDS2_SONAME "libfastrtps.so.2.14"
#define WRITER_GUID_NAME "_ZNK8eprosima7fastdds3dds14DataWriterImpl4guidEv"

// An action's services, by the end of their ROS name; rmw_fastrtps's reply topic is
// "rr" + that name + "Reply".
#define REPLY_PREFIX "rr/"
#define REPLY_SUFFIX "Reply"
static const char *const action_services[] = {"/_action/send_goal", "/_action/cancel_goal",
                                              "/_action/get_result"};

enum { MARKED = 0, WITHHELD = 1, PASSED = 2, IMPLAUSIBLE = 3, FULL = 4, COUNTERS = 5 };
static unsigned long counters[COUNTERS];
static void count(int which) { __atomic_fetch_add(&counters[which], 1, __ATOMIC_RELAXED); }

// CFT_GUARD_REPLIES: on unless "off" or "0", and only where the guard knows the Fast DDS 2.14.
static bool replies_on(void) {
  static int on = -1;  // -1: not read yet
  return cft_guard_part_on(&on, "CFT_GUARD_REPLIES", CFT_LAYOUT_KNOWN);
}

bool cft_replies_wanted(void) { return !cft_env_off("CFT_GUARD_REPLIES"); }

// Whether `name` ends in one of an action's service names, after at least one character, and then
// in `tail` (a ROS service name: ""; rmw_fastrtps's reply topic: "Reply").
static bool is_action_service(const char *name, const char *tail) {
  if (!cft_ends_with(name, tail)) return false;
  size_t n = strlen(name), t = strlen(tail);
  for (size_t i = 0; i < sizeof action_services / sizeof action_services[0]; i++) {
    size_t m = strlen(action_services[i]);
    if (n > m + t && strncmp(name + n - t - m, action_services[i], m) == 0) return true;
  }
  return false;
}

static bool is_action_reply_topic(const char *topic) {
  return strncmp(topic, REPLY_PREFIX, strlen(REPLY_PREFIX)) == 0 &&
         strlen(topic) > strlen(REPLY_PREFIX) && is_action_service(topic + 2, REPLY_SUFFIX);
}

bool cft_replies_is_action_service(const char *service_name) {
  return service_name != NULL && is_action_service(service_name, "");
}

static void say_routed(const char *name) {
  if (cft_debug_enabled())
    cft_say("reply writer of %.200s: each reply goes to the requesting participant's readers", name);
}

void cft_replies_writer_routed(const char *service_name) {
  count(MARKED);
  say_routed(service_name);
}

// ---- the marks: the GUIDs of the reply writers -----------------------------------------------------
// Open addressing, never removed (a GUID is not reused), so a lookup needs no lock: a slot's GUID
// is written before its `used` flag (release), under marks_lock.
#define MARK_SLOTS 4096
#define PROBE 32
static struct mark {
  uint8_t guid[16];
  int used;
} marks[MARK_SLOTS];
static pthread_mutex_t marks_lock = PTHREAD_MUTEX_INITIALIZER;
static unsigned long marked_writers;  // for the lock-free "none" of every other writer's changes

static unsigned slot_of(const uint8_t *guid) {
  uint64_t a, b;
  memcpy(&a, guid, 8);
  memcpy(&b, guid + 8, 8);
  uint64_t h = (a ^ (b * 0x9E3779B97F4A7C15ull)) * 0xBF58476D1CE4E5B9ull;
  return (unsigned)((h ^ (h >> 31)) % MARK_SLOTS);
}

static bool is_marked(const uint8_t *guid) {
  unsigned home = slot_of(guid);
  for (unsigned i = 0; i < PROBE; i++) {
    struct mark *m = &marks[(home + i) % MARK_SLOTS];
    if (!__atomic_load_n(&m->used, __ATOMIC_ACQUIRE)) return false;
    if (memcmp(m->guid, guid, 16) == 0) return true;
  }
  return false;
}

static void mark(const uint8_t *guid) {
  pthread_mutex_lock(&marks_lock);
  unsigned home = slot_of(guid);
  bool done = false;
  for (unsigned i = 0; i < PROBE && !done; i++) {
    struct mark *m = &marks[(home + i) % MARK_SLOTS];
    if (m->used) {
      done = memcmp(m->guid, guid, 16) == 0;
      continue;
    }
    memcpy(m->guid, guid, 16);
    __atomic_store_n(&m->used, 1, __ATOMIC_RELEASE);
    __atomic_fetch_add(&marked_writers, 1, __ATOMIC_RELEASE);
    count(MARKED);
    done = true;
  }
  pthread_mutex_unlock(&marks_lock);
  if (!done) count(FULL);
}

// ---- the hooks ---------------------------------------------------------------------------------------
typedef const uint8_t *(*writer_guid_fn)(const void *self);
static void *real_writer_guid;  // cft_guard_real's cache

void cft_replies_reader_matched(const void *writer, const void *reader_guid, const void *reader_info) {
  if (!replies_on()) return;
  const char *topic = cft_filter_reader_topic(reader_info, reader_guid);
  if (topic == NULL || !is_action_reply_topic(topic)) return;
  writer_guid_fn guid_of =
      (writer_guid_fn)cft_guard_real(&real_writer_guid, FASTDDS2_SONAME, WRITER_GUID_NAME);
  const uint8_t *guid = guid_of != NULL ? guid_of(writer) : NULL;
  if (guid == NULL || is_marked(guid)) return;
  mark(guid);
  say_routed(topic);
}

int cft_reply_verdict(const uint8_t *related, int32_t high, uint32_t low,
                      const uint8_t *reader_guid) {
  static const uint8_t unknown[16];
  // Most changes (feedback, status, anything but replies and requests) have no related identity.
  if (reader_guid == NULL || memcmp(related, unknown, sizeof unknown) == 0) return -1;
  uint8_t entity_kind = related[15];
  bool user_entity = entity_kind == 0x02 || entity_kind == 0x03 || entity_kind == 0x04 ||
                     entity_kind == 0x07;
  if (!user_entity || high < 0 || (high == 0 && low == 0)) {
    count(IMPLAUSIBLE);
    return -1;
  }
  if (memcmp(related, reader_guid, 12) == 0) {
    count(PASSED);
    return -1;
  }
  count(WITHHELD);
  return 0;
}

int cft_replies_relevance(const void *change, const void *reader_guid) {
  if (__atomic_load_n(&marked_writers, __ATOMIC_ACQUIRE) == 0 || reader_guid == NULL) return -1;
#if CFT_LAYOUT_KNOWN
  static const uint8_t unknown[16];
  const uint8_t *c = change;
  const uint8_t *related = c + CC_RELATED_WRITER_GUID;
  if (memcmp(related, unknown, sizeof unknown) == 0 || !is_marked(c + CC_WRITER_GUID)) return -1;
  uint32_t kind, low;
  int32_t high;
  _Static_assert(CC_KIND_SIZE == sizeof kind, "ChangeKind_t is not 4 bytes");
  memcpy(&kind, c + CC_KIND, sizeof kind);
  memcpy(&high, c + CC_RELATED_SEQUENCE, sizeof high);
  memcpy(&low, c + CC_RELATED_SEQUENCE + sizeof high, sizeof low);
  if (kind != 0) return -1;
  return cft_reply_verdict(related, high, low, reader_guid);
#else
  (void)change;
  return -1;
#endif
}

// ---- the C API, for ctypes -----------------------------------------------------------------------------
// 0: reply writers marked; 1: verdicts that withheld a reply from a reader of another participant;
// 2: verdicts for readers of the requesting participant (left to Fast DDS: delivered); 3: replies
// of marked writers whose identity did not read as rmw writes it (sent to all); 4: reply writers
// left unmarked because the table was full (their replies go to all).
CFT_EXPORT unsigned long cft_guard_reply_count(int which) {
  return which >= 0 && which < COUNTERS ? __atomic_load_n(&counters[which], __ATOMIC_RELAXED) : 0;
}
