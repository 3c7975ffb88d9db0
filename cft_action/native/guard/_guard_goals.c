// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// Whose goal is it: the participant that requested each goal the server took, for the parts that
// send a goal's samples only to its client (the status filter, _guard_status.c; the feedback
// verdict, _guard_feedback.c), in a process of either Fast DDS family.
//
// The server takes each goal request through rmw_take_request (rcl_action's
// rcl_action_take_goal_request -> rcl_take_request, from librcl into rmw_implementation), which is
// interposed here: for a service whose name ends in `/_action/send_goal`, the request's first
// member is its goal_id (the C and the C++ type support both put the UUID's 16 bytes first), and
// the request header's writer GUID names the client's participant (its first 12 bytes, the GUID
// prefix, are every endpoint's of that participant). The layouts of rmw_service_t and
// rmw_service_info_t come from rmw's headers (setup.py's rmw probe, RMW_SERVICE_NAME and
// RMW_INFO_WRITER_GUID in _fastdds_layout.h: Jazzy's and Kilted's wheels ship them); without them
// nothing is recorded and every goal is anyone's (its samples go to every reader).
//
// The first request for a goal UUID names its requester: one from another participant with the
// same UUID (which the server rejects, as a goal it already has) must not take the goal's samples
// from the client that requested it (any participant can read the goal UUIDs off the status
// topic, and send such requests). The record holds REQUESTER_SLOTS / 2 goals; when it is full it
// is cleared, and the goals taken before then are anyone's until the server forgets them.
// rmw_take_request always calls the next definition after the guard's.

#define _GNU_SOURCE
#include "_guard_goals.h"

#include <pthread.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include "_fastdds_layout.h"
#include "_guard_families.h"
#include "_guard_log.h"
#include "_guard_text.h"

#define TAKE_REQUEST "rmw_take_request"
#define GOAL_SERVICE_SUFFIX "/_action/send_goal"

#if defined(RMW_SERVICE_NAME) && defined(RMW_INFO_WRITER_GUID) && defined(RMW_GUID_SIZE)
#define RMW_LAYOUT_KNOWN 1
_Static_assert(RMW_GUID_SIZE == 16, "rmw's writer_guid is not a 16-byte GUID");
#else
#define RMW_LAYOUT_KNOWN 0
#endif

static unsigned long counters[CFT_GOALS_COUNTERS];

uint64_t cft_uuid_mix(const uint8_t *uuid) {
  uint64_t a, b;
  memcpy(&a, uuid, 8);
  memcpy(&b, uuid + 8, 8);
  uint64_t h = (a ^ (b * 0x9E3779B97F4A7C15ull)) * 0xBF58476D1CE4E5B9ull;
  return h ^ (h >> 31);
}

// ---- the requesters: goal UUID -> the requesting participant's GUID prefix -----------------------
#define REQUESTER_SLOTS (1u << 16)
struct requester {
  uint8_t uuid[CFT_UUID_SIZE];
  uint8_t prefix[CFT_PREFIX_SIZE];
  bool used;
};
static struct requester *requesters;  // REQUESTER_SLOTS, allocated with the first request
static pthread_mutex_t requesters_lock = PTHREAD_MUTEX_INITIALIZER;

static struct requester *requester_slot(const uint8_t *uuid) {
  unsigned mask = REQUESTER_SLOTS - 1;
  for (unsigned i = (unsigned)cft_uuid_mix(uuid) & mask;; i = (i + 1) & mask)
    if (!requesters[i].used || memcmp(requesters[i].uuid, uuid, CFT_UUID_SIZE) == 0)
      return &requesters[i];
}

enum cft_goal_owner cft_goal_owner(const uint8_t *uuid, const uint8_t *reader_guid) {
  enum cft_goal_owner owner = CFT_GOAL_UNKNOWN;
  pthread_mutex_lock(&requesters_lock);
  if (requesters != NULL) {
    const struct requester *r = requester_slot(uuid);
    if (r->used)
      owner = memcmp(r->prefix, reader_guid, CFT_PREFIX_SIZE) == 0 ? CFT_GOAL_READERS
                                                                   : CFT_GOAL_OTHERS;
  }
  pthread_mutex_unlock(&requesters_lock);
  return owner;
}

static void count(int which) { __atomic_fetch_add(&counters[which], 1, __ATOMIC_RELAXED); }

static unsigned requester_count;  // under requesters_lock

static void clear_locked(void) {
  if (requesters != NULL) memset(requesters, 0, REQUESTER_SLOTS * sizeof *requesters);
  requester_count = 0;
}

void cft_goals_clear(void) {
  pthread_mutex_lock(&requesters_lock);
  clear_locked();
  pthread_mutex_unlock(&requesters_lock);
}

void cft_goals_record(const uint8_t *uuid, const uint8_t *guid) {
  bool contested = false;
  pthread_mutex_lock(&requesters_lock);
  if (requesters == NULL) requesters = calloc(REQUESTER_SLOTS, sizeof *requesters);
  if (requesters != NULL) {
    if (requester_count >= REQUESTER_SLOTS / 2) {
      clear_locked();
      count(CFT_GOALS_RESETS);
    }
    struct requester *r = requester_slot(uuid);
    if (r->used && memcmp(r->prefix, guid, CFT_PREFIX_SIZE) != 0) {
      contested = true;  // said below, outside the lock
    } else {
      if (!r->used) requester_count++;
      memcpy(r->uuid, uuid, CFT_UUID_SIZE);
      memcpy(r->prefix, guid, CFT_PREFIX_SIZE);
      r->used = true;
      count(CFT_GOALS_REQUESTS);
    }
  }
  pthread_mutex_unlock(&requesters_lock);
  if (contested) {
    count(CFT_GOALS_CONTESTED);
    static bool said;
    if (cft_first(&said))
      cft_say("a goal request for a goal that another participant had requested: the first "
              "requester keeps the goal's status and feedback (the server rejects such a "
              "request; said once, cft_action.guard.status_counts()['contested'] counts each)");
  }
}

// The definition of rmw_take_request that rcl would have called: rmw_implementation's (rclpy loads
// it in a local scope, and the wheels rename it). Looked up once, outside Fast DDS.
typedef int32_t (*take_request_fn)(const void *service, void *header, void *request, bool *taken);

CFT_EXPORT int32_t rmw_take_request(const void *service, void *request_header, void *ros_request,
                                    bool *taken);
static take_request_fn real_take_request;
static pthread_once_t take_request_once = PTHREAD_ONCE_INIT;
static void resolve_take_request(void) {
  real_take_request = (take_request_fn)cft_guard_loaded_symbol(TAKE_REQUEST, "rmw_implementation");
}

int32_t rmw_take_request(const void *service, void *request_header, void *ros_request,
                         bool *taken) {
  pthread_once(&take_request_once, resolve_take_request);
  take_request_fn real = real_take_request;
  if (real == NULL) {
    cft_say("no rmw_take_request after the guard's: a service request cannot be taken");
    return 1;  // RMW_RET_ERROR
  }
  int32_t ret = real(service, request_header, ros_request, taken);
#if RMW_LAYOUT_KNOWN
  if (ret == 0 && taken != NULL && *taken && service != NULL && request_header != NULL &&
      ros_request != NULL) {
    const char *name;
    memcpy(&name, (const uint8_t *)service + RMW_SERVICE_NAME, sizeof name);
    if (name != NULL && cft_ends_with(name, GOAL_SERVICE_SUFFIX)) {
      const uint8_t *guid = (const uint8_t *)request_header + RMW_INFO_WRITER_GUID;
      uint8_t kind = guid[15];  // a user writer's (0x02, 0x03) or reader's (0x04, 0x07)
      if (kind == 0x02 || kind == 0x03 || kind == 0x04 || kind == 0x07)
        cft_goals_record(ros_request, guid);
      else
        count(CFT_GOALS_IMPLAUSIBLE);
    }
  }
#endif
  return ret;
}

unsigned long cft_goals_count(int which) {
  return which >= 0 && which < CFT_GOALS_COUNTERS
             ? __atomic_load_n(&counters[which], __ATOMIC_RELAXED) : 0;
}
