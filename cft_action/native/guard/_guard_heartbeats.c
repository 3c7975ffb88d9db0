// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's fourth part: a filtered writer's HEARTBEATs and GAPs reach the readers of the
// samples, not every reader at every write.
//
// A Fast DDS 2.14 StatefulWriter sends each new change to the readers it is relevant to, in one
// message. Two more things go out per write, as datagrams of their own, to every filtered reader
// the change is NOT for, which plain readers never see because they get the DATA anyway
// (docs/BENCHMARKS.md, "Read this first": at rclpy's default feedback depth of 10, N = 16 filtered
// clients received 0.79x plain's bytes at 36 B on 2.14.5 and 1.39x on 2.14.6, and the server spent
// up to 2x plain's CPU per message):
//
// 1. A HEARTBEAT to all readers. StatefulWriter::send_heartbeat_piggyback_nts_ calls
//    select_all_readers_nts, which widens the message to every reader, when the writer's history
//    is full (a keep-last-10 writer nearly always is), when acknowledgements lag, or when its byte
//    budget is spent. The definition of select_all_readers_nts below keeps that HEARTBEAT with the
//    DATA, to the DATA's readers (CFT_GUARD_HEARTBEAT_ALL_MS: `never`, the default; a number of ms
//    lets the widening through at most that often per writer; `off`: always). By default a status
//    writer's (a write on which a kept status reader was judged) goes through at most once per
//    STATUS_HEARTBEAT_ALL_MS: its readers' acknowledgements end the guard's owed chains (N = 16
//    clients x 4 goals: 58 status samples per client with it, 169 without, of 192). A reader the DATA
//    is not for learns the writer's range from the personal GAP and HEARTBEAT before its next DATA
//    and from the periodic heartbeat, which every other caller of select_all_readers_nts sends and
//    which goes through. A writer without filtered readers has every reader selected already, so
//    nothing changes for it or for plain readers.
// 2. From 2.14.6 (eProsima/Fast-DDS #6181), a GAP for the reader's run of filtered-out changes:
//    deliver_sample_to_network begins with add_gaps_for_removed_irrelevants for every reader with
//    such a run. The definition below drops the calls made from there. The run stays recorded in
//    the ReaderProxy, and goes out with the reader's next DATA (a personal GAP and HEARTBEAT
//    before it), with a NACK response, or with the periodic heartbeat, which then goes to each
//    reader separately, the GAP first; as 2.14.5 sends it (CFT_GUARD_DEFER_GAPS=0 turns it off).
//
// Both members are exported and called through the PLT; the callers are told by the return
// address, whose symbol dladdr names once per call site. Both act only where the guard locks the
// Fast DDS 2.14 it knows (cft_guard_knows_fastdds2); elsewhere every call goes through.

#define _GNU_SOURCE
#include <dlfcn.h>
#include <limits.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "_guard.h"
#include "_guard_log.h"
#include "_guard_status.h"

#define FASTDDS2_SONAME "libfastrtps.so.2.14"
#define SW_PREFIX "_ZN8eprosima8fastrtps4rtps14StatefulWriter"
#define SELECT_ALL                                                                             \
  SW_PREFIX "22select_all_readers_ntsERNS1_16RTPSMessageGroupERNS1_21LocatorSelectorSenderE"
#define ADD_GAPS \
  SW_PREFIX "32add_gaps_for_removed_irrelevantsERNS1_11ReaderProxyERNS1_16RTPSMessageGroupE"
// The callers, by the prefix of their mangled names (their parameters follow).
#define PIGGYBACK_CALLER SW_PREFIX "29send_heartbeat_piggyback_nts_"
#define DELIVER_CALLER SW_PREFIX "25deliver_sample_to_network"

enum { NARROWED = 0, WIDENED = 1, GAPS_DEFERRED = 2, GAPS_PASSED = 3, COUNTERS = 4 };
static unsigned long counters[COUNTERS];

static void count(int which) { __atomic_fetch_add(&counters[which], 1, __ATOMIC_RELAXED); }

// ---- the callers -----------------------------------------------------------------------------
// The call sites seen so far, and which caller each is in: a handful at most. A slot's `caller` is
// written before its address is published (release), under sites_lock.
enum { OTHER = 0, PIGGYBACK = 1, DELIVER = 2 };
#define SITES 16
static struct site {
  uintptr_t address;  // 0: free
  int caller;
} sites[SITES];
static pthread_mutex_t sites_lock = PTHREAD_MUTEX_INITIALIZER;

static int name_caller(uintptr_t address) {
  Dl_info info;
  if (!dladdr((void *)address, &info) || info.dli_sname == NULL) return OTHER;
  if (strncmp(info.dli_sname, PIGGYBACK_CALLER, strlen(PIGGYBACK_CALLER)) == 0) return PIGGYBACK;
  if (strncmp(info.dli_sname, DELIVER_CALLER, strlen(DELIVER_CALLER)) == 0) return DELIVER;
  return OTHER;
}

// Which caller the call returning to `address` is in.
static int caller_of(uintptr_t address) {
  for (int i = 0; i < SITES; i++) {
    uintptr_t known = __atomic_load_n(&sites[i].address, __ATOMIC_ACQUIRE);
    if (known == address) return sites[i].caller;
    if (known == 0) break;
  }
  int caller = OTHER;  // more call sites than slots: let the call through
  pthread_mutex_lock(&sites_lock);
  for (int i = 0; i < SITES; i++) {
    uintptr_t known = __atomic_load_n(&sites[i].address, __ATOMIC_RELAXED);
    if (known == address) {
      caller = sites[i].caller;
      break;
    }
    if (known != 0) continue;
    caller = sites[i].caller = name_caller(address);
    __atomic_store_n(&sites[i].address, address, __ATOMIC_RELEASE);
    break;
  }
  pthread_mutex_unlock(&sites_lock);
  return caller;
}

// ---- the switches --------------------------------------------------------------------------
// CFT_GUARD_HEARTBEAT_ALL_MS: at most one HEARTBEAT to all readers per this many ms per writer
// from the piggyback; "never" (the default): none; "off": as Fast DDS. -1 when off, NEVER when
// never, else nanoseconds.
#define NEVER LONG_MAX
#define STATUS_HEARTBEAT_ALL_MS 10
static long heartbeat_all_ns(void) {
  static long interval = -2;  // -2: not read yet
  long v = __atomic_load_n(&interval, __ATOMIC_RELAXED);
  if (v != -2) return v;
  const char *text = getenv("CFT_GUARD_HEARTBEAT_ALL_MS");
  if (text == NULL || text[0] == '\0' || strcmp(text, "never") == 0) {
    v = NEVER;
  } else if (strcmp(text, "off") == 0) {
    v = -1;
  } else {
    char *end;
    long ms = strtol(text, &end, 10);
    v = ms * 1000000L;
    if (*end != '\0' || ms < 0 || ms > 60000) {
      cft_say("CFT_GUARD_HEARTBEAT_ALL_MS=%.40s is not never, off or a number of ms from 0 to "
              "60000; using never", text);
      v = NEVER;
    }
  }
  if (!cft_guard_knows_fastdds2()) v = -1;
  __atomic_store_n(&interval, v, __ATOMIC_RELAXED);
  return v;
}

static bool gaps_deferred(void) {
  static int enabled = -1;  // -1: not read yet
  int e = __atomic_load_n(&enabled, __ATOMIC_RELAXED);
  if (e >= 0) return e;
  const char *off = getenv("CFT_GUARD_DEFER_GAPS");
  e = !(off != NULL && strcmp(off, "0") == 0) && cft_guard_knows_fastdds2();
  __atomic_store_n(&enabled, e, __ATOMIC_RELAXED);
  return e;
}

// ---- 1. the HEARTBEAT to all readers ------------------------------------------------------------
// When each writer last heartbeat all readers from the piggyback, in hashed slots. The piggyback
// runs under the writer's own mutex, so only colliding writers share a slot: the newcomer takes
// it over and is let through, as Fast DDS would.
#define WRITER_SLOTS 256
static struct {
  uintptr_t writer;
  long last_ns;
} writer_slots[WRITER_SLOTS];

static long now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec * 1000000000L + ts.tv_nsec;
}

static bool widening_due(uintptr_t writer, long interval) {
  unsigned slot = (unsigned)(((uint64_t)writer >> 4) * 0x9E3779B97F4A7C15ull >> 56);
  long now = now_ns();
  if (__atomic_load_n(&writer_slots[slot].writer, __ATOMIC_RELAXED) != writer) {
    __atomic_store_n(&writer_slots[slot].writer, writer, __ATOMIC_RELAXED);
    __atomic_store_n(&writer_slots[slot].last_ns, now, __ATOMIC_RELAXED);
    return true;
  }
  if (now - __atomic_load_n(&writer_slots[slot].last_ns, __ATOMIC_RELAXED) < interval)
    return false;
  __atomic_store_n(&writer_slots[slot].last_ns, now, __ATOMIC_RELAXED);
  return true;
}

typedef void (*select_all_fn)(void *self, void *group, void *locator_selector);
static void *real_select_all;

CFT_EXPORT void cft_select_all_readers_nts2(void *self, void *group, void *locator_selector)
    __asm__(SELECT_ALL);
void cft_select_all_readers_nts2(void *self, void *group, void *locator_selector) {
  long interval = heartbeat_all_ns();
  if (interval == NEVER && cft_status_write_now()) interval = STATUS_HEARTBEAT_ALL_MS * 1000000L;
  if (interval >= 0 && caller_of((uintptr_t)__builtin_return_address(0)) == PIGGYBACK) {
    if (interval == NEVER || !widening_due((uintptr_t)self, interval)) {
      count(NARROWED);
      return;
    }
    count(WIDENED);
  }
  select_all_fn real =
      (select_all_fn)cft_guard_real(&real_select_all, FASTDDS2_SONAME, SELECT_ALL);
  if (real != NULL) real(self, group, locator_selector);  // else unreachable: Fast DDS called us
}

// ---- 2. the per-write GAPs of 2.14.6 -----------------------------------------------------------
typedef void (*add_gaps_fn)(void *self, void *reader_proxy, void *group);
static void *real_add_gaps;

CFT_EXPORT void cft_add_gaps_for_removed_irrelevants2(void *self, void *reader_proxy, void *group)
    __asm__(ADD_GAPS);
void cft_add_gaps_for_removed_irrelevants2(void *self, void *reader_proxy, void *group) {
  if (gaps_deferred() && caller_of((uintptr_t)__builtin_return_address(0)) == DELIVER) {
    count(GAPS_DEFERRED);
    return;
  }
  add_gaps_fn real = (add_gaps_fn)cft_guard_real(&real_add_gaps, FASTDDS2_SONAME, ADD_GAPS);
  if (real == NULL) return;  // unreachable: only that Fast DDS calls this member
  count(GAPS_PASSED);
  real(self, reader_proxy, group);
}

// 0: piggyback HEARTBEATs kept to the DATA's readers; 1: let through to all readers;
// 2: per-write GAPs left for later; 3: GAPs of the other kinds.
CFT_EXPORT unsigned long cft_guard_heartbeat_count(int which) {
  return which >= 0 && which < COUNTERS ? __atomic_load_n(&counters[which], __ATOMIC_RELAXED) : 0;
}
