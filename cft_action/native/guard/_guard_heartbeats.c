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
// 3. What plain readers see: the piggyback HEARTBEAT rides in the DATA's datagram at every write
//    while the history is full, and filtered readers keep a keep-last-10 history full (a volatile
//    writer drops a change once every reader acknowledged it; a filtered reader acknowledges
//    others' changes only when a GAP or HEARTBEAT reaches it), where plain readers'
//    acknowledgements empty it about every other write: beside 32 filtered clients a plain one
//    received 16-17 B more per 36 B sample. In a write that judged both a reader the guard keeps
//    (_guard_filter.c) and another (a plain one), the definition of send_heartbeat_nts_ below lets
//    the piggyback's HEARTBEAT go at most once per CFT_GUARD_PIGGYBACK_MS (10 by default; `off`:
//    every write) per writer; a widened one always goes, and a status writer's too (the
//    acknowledgements it asks for end the owed chains of _guard_status.c: spaced out, N = 16
//    clients x 4 goals got 166 status samples per client in one run). With filtered readers only,
//    every HEARTBEAT goes, as in Fast DDS (spaced, their bytes were the same: N = 16 x 4 goals,
//    deep history, 11.8 B per own payload byte besides status either way). Readers learn the
//    range at most that much later; HEARTBEATs of other callers (the personal one before a
//    filtered reader's DATA, the periodic one) go through.
// 4. The personal GAP, in the DATA's datagram. For a reader with a run of changes filtered out for
//    it before the one it gets, deliver_sample_to_network first sends a GAP for the run and a
//    HEARTBEAT to that reader alone, in a datagram of their own (it switches the message group's
//    sender to the reader and back, which flushes it), then the DATA: a filtered client got one per
//    own sample that follows others' (160 B of UDP payload; in the DATA's datagram they take 64 B,
//    as a capture on loopback showed). In a write whose change goes to one reader (the write's
//    frame counts the readers passed), not a status writer's, the definitions of add_gap and
//    send_heartbeat_nts_ below hold both back on the thread, and add_data (add_data_frag) of the
//    same group, writer and change adds them before its DATA, with one HEARTBEAT after the GAP:
//    INFO_DST scopes the GAP to its reader, the HEARTBEAT and DATA go to the same reader, and the
//    flush between sends nothing (RTPSMessageGroup::send skips a message of only its header). One
//    reader only: Fast DDS's receivers keep an INFO_DST's destination to the datagram's end (one of
//    GUIDPREFIX_UNKNOWN changes nothing), so that a DATA after a GAP would be lost to the other
//    participants it goes to (a plain client beside routed ones lost all its feedback so, in a
//    prototype on 3.6.2). A writer GUID read wrong (the DATA's change names another) stops
//    merging, said once. CFT_GUARD_MERGE_GAPS=0
//    turns it off. N = 16 clients x 4 goals at depth 10, 3 runs each way: the first client got 2-3
//    gap/heartbeat datagrams instead of 403-804, and 7.2-8.5 B of feedback per own payload byte
//    instead of 9.5-12.5; the server's CPU per message did not change measurably. A reader gets its
//    GAP, a HEARTBEAT and its DATA in this order, as before. A GAP held that no DATA of its change
//    follows (an exception; not seen) is dropped and counted: the reader learns of the run from the
//    next HEARTBEAT and NACKs it, and the writer answers with a GAP. With separate sending (a
//    datagram per reader for the DATA: Fast DDS's builtin discovery-server and security writers,
//    never one with kept readers) the GAP goes at its HEARTBEAT, as in Fast DDS. The DATA's own
//    piggyback HEARTBEAT (a full history's), which would repeat the merged one to the same readers
//    with the same range, is left out.
//
// Fast DDS 3.4.2+ (Lyrical's 3.6) sends the same HEARTBEAT and GAPs (StatefulWriter.cpp of v3.6.2:
// deliver_sample_to_network, send_heartbeat_piggyback_nts_ with two parameters) to the readers a
// routed writer's prefilter withholds samples from (feedback, status: _guard_feedback.c,
// _guard_status.c): about two datagrams per withheld sample, which cost the server 2.1x plain's
// CPU per message at rclpy's feedback depth. Parts 1 and 2 act there too, in a write whose frame
// says it asked a routed reader's verdict (the prefilter runs in the write, under
// perform_create_new_change: _guard.c opens the frame), and nowhere else: other writers, and a
// write delivered by another thread (an asynchronous publication mode), go as Fast DDS sends them.
// The real members are those of the library that called (cft_guard_real_in_caller). Part 4 acts
// there too, in the same writes, with what the layer reads of a change, a sequence number set and
// a writer through the headers it was built with (fastdds3/_rtps_types.h); a DataWriter there
// never sends separately (WriterAttributes::separate_sending is set for builtin writers only).
// N = 16 clients x 4 goals, depth 10, feedback and status routed: the first client 9.15 B per own
// payload byte (Jazzy 8.55-8.77), 1 lone GAP/HEARTBEAT datagram; with parts 1 and 2 only 0.19x
// plain's bytes per client and 603 lone datagrams (docs/BENCHMARKS.md).
//
// These members are exported and called through the PLT. A call from deliver_sample_to_network is
// told by the return address, whose symbol dladdr names once per call site; one from the
// piggyback by send_heartbeat_piggyback_nts_, defined here too (it reaches send_heartbeat_nts_ by a
// tail call, whose return address is its own caller's). They act only where the guard locks the
// Fast DDS 2.14 it knows (cft_guard_knows_fastdds2), or in a routed writer's write on Fast DDS 3;
// elsewhere every call goes through. On 2.14 part 4 reads the layouts of the headers the guard
// was built against (_fastdds_layout.h); without them it holds nothing back there.

#define _GNU_SOURCE
#include <dlfcn.h>
#include <limits.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "_fastdds_layout.h"
#include "_guard_families.h"
#include "_guard_log.h"
#include "_guard_status.h"
#include "_guard_text.h"

// On Fast DDS 2.14 part 4 reads these layouts of the headers the guard was built against; without
// them (no headers, or a layout header made up by a test) it holds nothing back there.
#if CFT_LAYOUT_KNOWN && defined(CC_SEQUENCE) && defined(CC_WRITER_GUID) && defined(SNS_SIZE) && \
    defined(SNS_BASE) && defined(SW_GUID) && defined(SW_SEPARATE_SENDING) &&                   \
    defined(CFT_LAYOUT_HAVE_SECURITY)
#define MERGE_LAYOUT_KNOWN 1
#else
#define MERGE_LAYOUT_KNOWN 0
#endif

#define FASTDDS2_SONAME "libfastrtps.so.2.14"
#define SW_PREFIX "_ZN8eprosima8fastrtps4rtps14StatefulWriter"
#define SELECT_ALL                                                                             \
  SW_PREFIX "22select_all_readers_ntsERNS1_16RTPSMessageGroupERNS1_21LocatorSelectorSenderE"
#define SEND_HEARTBEAT SW_PREFIX "19send_heartbeat_nts_EmRNS1_16RTPSMessageGroupEbb"
#define PIGGYBACK_MEMBER \
  SW_PREFIX "29send_heartbeat_piggyback_nts_ERNS1_16RTPSMessageGroupERNS1_21LocatorSelectorSenderERj"
#define ADD_GAPS \
  SW_PREFIX "32add_gaps_for_removed_irrelevantsERNS1_11ReaderProxyERNS1_16RTPSMessageGroupE"
// The caller told by the return address, by the prefix of its mangled name (its parameters follow).
#define DELIVER_CALLER SW_PREFIX "25deliver_sample_to_network"
// Fast DDS 3.4.2+ (Lyrical's 3.6): parts 1 and 2, for the writes of routed writers only.
#define SW3_PREFIX "_ZN8eprosima7fastdds4rtps14StatefulWriter"
#define SELECT_ALL3                                                                            \
  SW3_PREFIX "22select_all_readers_ntsERNS1_16RTPSMessageGroupERNS1_21LocatorSelectorSenderE"
#define PIGGYBACK_MEMBER3 \
  SW3_PREFIX "29send_heartbeat_piggyback_nts_ERNS1_16RTPSMessageGroupERNS1_21LocatorSelectorSenderE"
#define ADD_GAPS3 \
  SW3_PREFIX "32add_gaps_for_removed_irrelevantsERNS1_11ReaderProxyERNS1_16RTPSMessageGroupE"
#define DELIVER_CALLER3 SW3_PREFIX "25deliver_sample_to_network"

enum { NARROWED = 0, WIDENED = 1, GAPS_DEFERRED = 2, GAPS_PASSED = 3, PIGGYBACK_SPACED = 4,
       GAPS_MERGED = 5, MERGES_DROPPED = 6, PIGGYBACK_MERGED = 7, COUNTERS = 8 };
static unsigned long counters[COUNTERS];

static void count(int which) { __atomic_fetch_add(&counters[which], 1, __ATOMIC_RELAXED); }

// ---- the callers -----------------------------------------------------------------------------
// The call sites seen so far, and which caller each is in: a handful at most. A slot's `caller` is
// written before its address is published (release), under sites_lock.
enum { OTHER = 0, DELIVER = 1 };
#define SITES 16
static struct site {
  uintptr_t address;  // 0: free
  int caller;
} sites[SITES];
static pthread_mutex_t sites_lock = PTHREAD_MUTEX_INITIALIZER;

static int name_caller(uintptr_t address) {
  Dl_info info;
  if (!dladdr((void *)address, &info) || info.dli_sname == NULL) return OTHER;
  if (strncmp(info.dli_sname, DELIVER_CALLER, strlen(DELIVER_CALLER)) == 0 ||
      strncmp(info.dli_sname, DELIVER_CALLER3, strlen(DELIVER_CALLER3)) == 0)
    return DELIVER;
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

// The piggyback runs on this thread: select_all_readers_nts and send_heartbeat_nts_ called now are
// its own (the latter by a tail call, whose return address would name the piggyback's caller).
static __thread bool in_piggyback;
// The piggyback on this thread has just widened its HEARTBEAT to all readers: it goes out.
static __thread bool widened_now;
typedef void (*piggyback_fn)(void *self, void *group, void *locator_selector, uint32_t *bytes);
static void *real_piggyback;

CFT_EXPORT void cft_send_heartbeat_piggyback_nts2(void *self, void *group, void *locator_selector,
                                                  uint32_t *bytes) __asm__(PIGGYBACK_MEMBER);
void cft_send_heartbeat_piggyback_nts2(void *self, void *group, void *locator_selector,
                                       uint32_t *bytes) {
  piggyback_fn real =
      (piggyback_fn)cft_guard_real(&real_piggyback, FASTDDS2_SONAME, PIGGYBACK_MEMBER);
  if (real == NULL) return;  // unreachable: only that Fast DDS calls this member
  bool outer = in_piggyback;
  in_piggyback = true;
  real(self, group, locator_selector, bytes);
  in_piggyback = outer;
}

// Fast DDS 3.4.2+'s, with two parameters.
typedef void (*piggyback3_fn)(void *self, void *group, void *locator_selector);
static void *real_piggyback3;

CFT_EXPORT void cft_send_heartbeat_piggyback_nts3(void *self, void *group, void *locator_selector)
    __asm__(PIGGYBACK_MEMBER3);
void cft_send_heartbeat_piggyback_nts3(void *self, void *group, void *locator_selector) {
  piggyback3_fn real = (piggyback3_fn)cft_guard_real_in_caller(
      &real_piggyback3, PIGGYBACK_MEMBER3, __builtin_return_address(0));
  if (real == NULL) return;  // unreachable: only that Fast DDS calls this member
  bool outer = in_piggyback;
  in_piggyback = true;
  real(self, group, locator_selector);
  in_piggyback = outer;
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
  } else if ((v = cft_guard_ms_to_ns(text, 0, 60000)) < 0) {
    cft_say("CFT_GUARD_HEARTBEAT_ALL_MS=%.40s is not never, off or a number of ms from 0 to "
            "60000; using never", text);
    v = NEVER;
  }
  __atomic_store_n(&interval, v, __ATOMIC_RELAXED);
  return v;
}

// CFT_GUARD_PIGGYBACK_MS: in a write in which a kept reader was judged, the piggyback HEARTBEAT
// at most once per this many ms per writer (default PIGGYBACK_MS); "off" or 0: at every write, as
// Fast DDS. 0 when off, else nanoseconds.
#define PIGGYBACK_MS 10
static long piggyback_ns(void) {
  static long interval = -1;  // -1: not read yet
  return cft_guard_knows_fastdds2()
             ? cft_guard_env_ms(&interval, "CFT_GUARD_PIGGYBACK_MS", PIGGYBACK_MS, 0, 60000)
             : 0;
}

// CFT_GUARD_DEFER_GAPS: on unless "0".
static bool gaps_deferred(void) {
  static int enabled = -1;  // -1: not read yet
  int e = __atomic_load_n(&enabled, __ATOMIC_RELAXED);
  if (e >= 0) return e;
  const char *off = getenv("CFT_GUARD_DEFER_GAPS");
  e = !(off != NULL && strcmp(off, "0") == 0);
  __atomic_store_n(&enabled, e, __ATOMIC_RELAXED);
  return e;
}

// Where the guard acts on Fast DDS 3: in a write that asked the verdict of a reader it routes
// samples to (fastdds3/_prefilter.cpp: an action's feedback or status writer). Every other writer,
// and every write on a thread other than the writing one (asynchronous publication), stays as
// Fast DDS sends it.
static bool routed_write_now(void) { return (cft_write_judged_now() & CFT_KEPT_READER) != 0; }

// ---- 1. the HEARTBEAT to all readers ------------------------------------------------------------
// When each writer last heartbeat all readers from the piggyback, in hashed slots. The piggyback
// runs under the writer's own mutex, so only colliding writers share a slot: the newcomer takes
// it over and is let through, as Fast DDS would.
#define WRITER_SLOTS 256
struct writer_slot {
  uintptr_t writer;
  long last_ns;
};
static struct writer_slot widened_slots[WRITER_SLOTS];
static long now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec * 1000000000L + ts.tv_nsec;
}

// Whether `writer` may do it again, `interval` ns after it last did (by `slots`); if so, it did.
static bool due(struct writer_slot *slots, uintptr_t writer, long interval) {
  struct writer_slot *slot = &slots[((uint64_t)writer >> 4) * 0x9E3779B97F4A7C15ull >> 56];
  long now = now_ns();
  if (__atomic_load_n(&slot->writer, __ATOMIC_RELAXED) != writer) {
    __atomic_store_n(&slot->writer, writer, __ATOMIC_RELAXED);
    __atomic_store_n(&slot->last_ns, now, __ATOMIC_RELAXED);
    return true;
  }
  if (now - __atomic_load_n(&slot->last_ns, __ATOMIC_RELAXED) < interval) return false;
  __atomic_store_n(&slot->last_ns, now, __ATOMIC_RELAXED);
  return true;
}

typedef void (*select_all_fn)(void *self, void *group, void *locator_selector);
static void *real_select_all;

CFT_EXPORT void cft_select_all_readers_nts2(void *self, void *group, void *locator_selector)
    __asm__(SELECT_ALL);
// Whether the piggyback's select_all_readers_nts of `self` leaves its HEARTBEAT to the DATA's
// readers, `interval` being the writer's CFT_GUARD_HEARTBEAT_ALL_MS (-1: as Fast DDS).
static bool narrowed(void *self, long interval) {
  if (interval < 0 || !in_piggyback) return false;
  if (interval == NEVER || !due(widened_slots, (uintptr_t)self, interval)) {
    count(NARROWED);
    return true;
  }
  count(WIDENED);
  widened_now = true;
  return false;
}

void cft_select_all_readers_nts2(void *self, void *group, void *locator_selector) {
  long interval = cft_guard_knows_fastdds2() ? heartbeat_all_ns() : -1;
  if (cft_status_write_now()) {
    cft_status_writer(self);
    if (interval == NEVER) interval = STATUS_HEARTBEAT_ALL_MS * 1000000L;
  }
  if (narrowed(self, interval)) return;
  select_all_fn real =
      (select_all_fn)cft_guard_real(&real_select_all, FASTDDS2_SONAME, SELECT_ALL);
  if (real != NULL) real(self, group, locator_selector);  // else unreachable: Fast DDS called us
}

static void *real_select_all3;

CFT_EXPORT void cft_select_all_readers_nts3(void *self, void *group, void *locator_selector)
    __asm__(SELECT_ALL3);
void cft_select_all_readers_nts3(void *self, void *group, void *locator_selector) {
  long interval = routed_write_now() ? heartbeat_all_ns() : -1;
  if (interval == NEVER && cft_status_write_now()) interval = STATUS_HEARTBEAT_ALL_MS * 1000000L;
  if (narrowed(self, interval)) return;
  select_all_fn real = (select_all_fn)cft_guard_real_in_caller(&real_select_all3, SELECT_ALL3,
                                                               __builtin_return_address(0));
  if (real != NULL) real(self, group, locator_selector);  // else unreachable: Fast DDS called us
}

// ---- 2. the per-write GAPs of 2.14.6 -----------------------------------------------------------
typedef void (*add_gaps_fn)(void *self, void *reader_proxy, void *group);
static void *real_add_gaps;

CFT_EXPORT void cft_add_gaps_for_removed_irrelevants2(void *self, void *reader_proxy, void *group)
    __asm__(ADD_GAPS);
// Whether a call of add_gaps_for_removed_irrelevants returning to `return_address` is left out:
// one from deliver_sample_to_network (`acts`: in a write where the family's guard acts).
static bool gaps_left(bool acts, const void *return_address) {
  if (!acts || !gaps_deferred() || caller_of((uintptr_t)return_address) != DELIVER) return false;
  count(GAPS_DEFERRED);
  return true;
}

void cft_add_gaps_for_removed_irrelevants2(void *self, void *reader_proxy, void *group) {
  if (gaps_left(cft_guard_knows_fastdds2(), __builtin_return_address(0))) return;
  add_gaps_fn real = (add_gaps_fn)cft_guard_real(&real_add_gaps, FASTDDS2_SONAME, ADD_GAPS);
  if (real == NULL) return;  // unreachable: only that Fast DDS calls this member
  count(GAPS_PASSED);
  real(self, reader_proxy, group);
}

static void *real_add_gaps3;

CFT_EXPORT void cft_add_gaps_for_removed_irrelevants3(void *self, void *reader_proxy, void *group)
    __asm__(ADD_GAPS3);
void cft_add_gaps_for_removed_irrelevants3(void *self, void *reader_proxy, void *group) {
  const void *caller = __builtin_return_address(0);
  if (gaps_left(routed_write_now(), caller)) return;
  add_gaps_fn real = (add_gaps_fn)cft_guard_real_in_caller(&real_add_gaps3, ADD_GAPS3, caller);
  if (real == NULL) return;  // unreachable: only that Fast DDS calls this member
  count(GAPS_PASSED);
  real(self, reader_proxy, group);
}

// ---- 3. the piggyback HEARTBEAT itself, spaced out (CFT_GUARD_PIGGYBACK_MS) --------------------
static struct writer_slot piggyback_slots[WRITER_SLOTS];

typedef void (*send_heartbeat_fn)(void *self, size_t readers, void *group, bool final,
                                  bool liveliness);
static void *real_send_heartbeat;
// Part 4's, below.
static bool heartbeat_merged(void *self, void *group, bool final, bool liveliness,
                             send_heartbeat_fn real, const void *return_address,
                             bool (*separate)(const void *writer));
static bool repeats_merged(void *self, void *group);
static bool separate_sending(const void *writer);

// Whether the piggyback HEARTBEAT of `self` in `group`, not widened, repeats the one merged before
// its DATA: then it is left out (counted). *widened: whether the piggyback widened it.
static bool piggyback_repeats_merged(void *self, void *group, bool *widened) {
  *widened = widened_now;
  widened_now = false;
  if (*widened || !in_piggyback || !repeats_merged(self, group)) return false;
  count(PIGGYBACK_MERGED);
  return true;
}

CFT_EXPORT void cft_send_heartbeat_nts2(void *self, size_t readers, void *group, bool final,
                                        bool liveliness) __asm__(SEND_HEARTBEAT);
void cft_send_heartbeat_nts2(void *self, size_t readers, void *group, bool final,
                             bool liveliness) {
  send_heartbeat_fn real = (send_heartbeat_fn)cft_guard_real(&real_send_heartbeat,
                                                             FASTDDS2_SONAME, SEND_HEARTBEAT);
  if (real == NULL) return;  // unreachable: only that Fast DDS calls this member
  if (heartbeat_merged(self, group, final, liveliness, real, __builtin_return_address(0),
                       separate_sending))
    return;
  bool widened;
  if (piggyback_repeats_merged(self, group, &widened)) return;
  long interval = piggyback_ns();
  if (interval > 0 && !widened && in_piggyback &&
      cft_write_judged_now() == (CFT_KEPT_READER | CFT_OTHER_READER) && !cft_status_write_now() &&
      !due(piggyback_slots, (uintptr_t)self, interval)) {
    count(PIGGYBACK_SPACED);
    return;
  }
  real(self, readers, group, final, liveliness);
}

// Fast DDS 3.4.2+'s: part 4 only (part 3 acts on Fast DDS 2.14).
#define SEND_HEARTBEAT3 SW3_PREFIX "19send_heartbeat_nts_EmRNS1_16RTPSMessageGroupEbb"
static void *real_send_heartbeat3;

CFT_EXPORT void cft_send_heartbeat_nts3(void *self, size_t readers, void *group, bool final,
                                        bool liveliness) __asm__(SEND_HEARTBEAT3);
void cft_send_heartbeat_nts3(void *self, size_t readers, void *group, bool final,
                             bool liveliness) {
  const void *caller = __builtin_return_address(0);
  send_heartbeat_fn real =
      (send_heartbeat_fn)cft_guard_real_in_caller(&real_send_heartbeat3, SEND_HEARTBEAT3, caller);
  if (real == NULL) return;  // unreachable: only that Fast DDS calls this member
  // Fast DDS 3's DataWriters never send separately (WriterAttributes::separate_sending is set
  // for builtin writers only: v3.6.2's EDPServer, PDPServer, SecurityManager).
  bool widened;
  if (heartbeat_merged(self, group, final, liveliness, real, caller, NULL) ||
      piggyback_repeats_merged(self, group, &widened))
    return;
  real(self, readers, group, final, liveliness);
}

// ---- 4. the personal GAP and HEARTBEAT, in the DATA's datagram (CFT_GUARD_MERGE_GAPS) ----------
// What this part reads of a change, a sequence number set and a writer: on Fast DDS 2.14 the
// layouts of the headers the guard was built against (without them nothing is held back there),
// on Fast DDS 3 the layer's reading, through the headers it was built with (fastdds3/_rtps_types.h;
// NULL until the layer is loaded, and where it is not).
#define GUID_SIZE CFT_RTPS_GUID_SIZE
typedef bool (*add_gap_fn)(void *group, const void *seq, const void *set, const void *reader);

#if MERGE_LAYOUT_KNOWN
_Static_assert(SNS_SIZE <= CFT_RTPS_SET_MAX, "a held GAP copies SequenceNumberSet_t");
static void set_base2(const void *set, uint8_t sequence[CFT_SEQUENCE_SIZE]) {
  memcpy(sequence, (const uint8_t *)set + SNS_BASE, CFT_SEQUENCE_SIZE);
}
static void change_ids2(const void *change, uint8_t sequence[CFT_SEQUENCE_SIZE],
                        uint8_t writer_guid[GUID_SIZE]) {
  memcpy(sequence, (const uint8_t *)change + CC_SEQUENCE, CFT_SEQUENCE_SIZE);
  memcpy(writer_guid, (const uint8_t *)change + CC_WRITER_GUID, GUID_SIZE);
}
static void writer_guid2(const void *writer, uint8_t guid[GUID_SIZE]) {
  memcpy(guid, (const uint8_t *)writer + SW_GUID, GUID_SIZE);
}
static const struct cft_rtps_types types2 = {SNS_SIZE, set_base2, change_ids2, writer_guid2};
#endif

// Set when a GAP held back met its DATA with another writer's GUID than its HEARTBEAT's writer
// had: the reading of one of them is wrong (or an exception left a GAP of another writer): from
// then on nothing is held back, said once.
static int merge_broken;

// Fast DDS 2.14's reading, where CFT_GUARD_MERGE_GAPS is on (unless "off" or "0"), the headers'
// layouts are known and the guard knows that Fast DDS; else NULL.
static const struct cft_rtps_types *merge_types2(void) {
#if MERGE_LAYOUT_KNOWN
  static int on = -1;  // -1: not read yet
  if (cft_guard_part_on(&on, "CFT_GUARD_MERGE_GAPS", true) &&
      !__atomic_load_n(&merge_broken, __ATOMIC_RELAXED))
    return &types2;
#endif
  return NULL;
}

// Fast DDS 3's, where CFT_GUARD_MERGE_GAPS is on and the layer is loaded; else NULL.
static const struct cft_rtps_types *merge_types3(void) {
  static int on = -1;  // -1: not read yet
  if (!cft_guard_env_on(&on, "CFT_GUARD_MERGE_GAPS") ||
      __atomic_load_n(&merge_broken, __ATOMIC_RELAXED))
    return NULL;
  return cft_fastdds3_types();
}

#if MERGE_LAYOUT_KNOWN
// SecurityManager::cancel_init(), exported only by a Fast DDS built with SECURITY=ON, which
// moves RTPSWriter's members (m_separateSendingEnabled) from the headers' offsets.
#define SECURITY_ONLY_SYMBOL "_ZN8eprosima8fastrtps4rtps8security15SecurityManager11cancel_initEv"
#endif

// Whether a Fast DDS 2.14 `writer` sends each reader's DATA in a datagram of its own
// (m_separateSendingEnabled). In Fast DDS 2.14 only builtin writers do (the discovery server's,
// security's), which write in no frame that judged kept readers. The flag is read where its offset
// is known: the headers', when the loaded library's HAVE_SECURITY, which moves it, is theirs (apt's
// 2.14.6 beside the wheels' headers is not).
static bool separate_sending(const void *writer) {
#if MERGE_LAYOUT_KNOWN
  static int offset_known = -1;  // -1: not decided yet
  static void *security_symbol;
  int known = __atomic_load_n(&offset_known, __ATOMIC_RELAXED);
  if (known < 0) {
    bool loaded_security =
        cft_guard_real(&security_symbol, FASTDDS2_SONAME, SECURITY_ONLY_SYMBOL) != NULL;
    known = loaded_security == CFT_LAYOUT_HAVE_SECURITY;
    __atomic_store_n(&offset_known, known, __ATOMIC_RELAXED);
  }
  bool separate = false;
  if (known) memcpy(&separate, (const uint8_t *)writer + SW_SEPARATE_SENDING, sizeof separate);
  return separate;
#else
  (void)writer;
  return false;
#endif
}

// A personal GAP held back on this thread, with the HEARTBEAT that followed it. Those held share
// their group and their change (the set's base): a GAP of another is added after dropping them.
// One per reader with a run that the change goes to (one, for a client's feedback); past HELD a
// GAP goes at once, as in Fast DDS.
#define HELD 4
struct held {
  void *group;                         // the RTPSMessageGroup it was added to
  const struct cft_rtps_types *types;  // its family's reading
  add_gap_fn add_gap;                  // the real member Fast DDS called
  void *writer;                        // the StatefulWriter whose HEARTBEAT followed; NULL: none yet
  send_heartbeat_fn send_heartbeat;    // the real member it called
  uint8_t writer_guid[GUID_SIZE];      // its GUID, to tell its DATA
  bool final, liveliness;              // that send_heartbeat_nts_'s arguments
  uint8_t seq[CFT_SEQUENCE_SIZE];      // add_gap's arguments: the first sequence number of the run,
  uint8_t set[CFT_RTPS_SET_MAX];       // the set, whose base is the change of the DATA that follows
  uint8_t base[CFT_SEQUENCE_SIZE];     // (that base),
  uint8_t reader[GUID_SIZE];           // and the reader
};
static __thread struct held held[HELD];
static __thread int held_count;
// The GAP just held back: the send_heartbeat_nts_ that follows it is its own.
static __thread struct held *awaiting_heartbeat;
// The group and writer of the HEARTBEAT that merge_held added before this DATA, if it added one.
static __thread void *merged_group, *merged_writer;

static void drop_held(void) {
  for (int i = 0; i < held_count; i++) count(MERGES_DROPPED);
  held_count = 0;
  awaiting_heartbeat = NULL;
}

// Whether add_gap's GAP is held back (`types`: the family's reading, NULL when nothing may be held
// back now; `real`: the member).
static bool gap_held(const struct cft_rtps_types *types, add_gap_fn real,
                     const void *return_address, void *group, const void *seq, const void *set,
                     const void *reader) {
  if (types == NULL || real == NULL || caller_of((uintptr_t)return_address) != DELIVER)
    return false;
  uint8_t base[CFT_SEQUENCE_SIZE];
  types->set_base(set, base);
  if (held_count > 0 && (held[0].group != group || memcmp(held[0].base, base, sizeof base) != 0))
    drop_held();
  if (held_count == HELD) return false;
  struct held *h = &held[held_count++];
  h->group = group;
  h->types = types;
  h->add_gap = real;
  h->writer = NULL;
  memcpy(h->seq, seq, sizeof h->seq);
  memcpy(h->set, set, types->set_size);
  memcpy(h->base, base, sizeof h->base);
  memcpy(h->reader, reader, sizeof h->reader);
  awaiting_heartbeat = h;
  return true;
}

#define GROUP_PREFIX "_ZN8eprosima8fastrtps4rtps16RTPSMessageGroup"
#define ADD_GAP                                                                                 \
  GROUP_PREFIX "7add_gapERKNS1_16SequenceNumber_tERKNS0_11BitmapRangeIS3_NS1_18SequenceNumberDiff" \
               "ELj256EEERKNS1_6GUID_tE"
#define ADD_DATA GROUP_PREFIX "8add_dataERKNS1_13CacheChange_tEb"
#define ADD_DATA_FRAG GROUP_PREFIX "13add_data_fragERKNS1_13CacheChange_tEjb"
#define GROUP3_PREFIX "_ZN8eprosima7fastdds4rtps16RTPSMessageGroup"
#define ADD_GAP3                                                                                 \
  GROUP3_PREFIX "7add_gapERKNS1_16SequenceNumber_tERKNS0_11BitmapRangeIS3_NS1_18SequenceNumberDiff" \
                "ELj256EEERKNS1_6GUID_tE"
#define ADD_DATA3 GROUP3_PREFIX "8add_dataERNS1_13CacheChange_tEb"
#define ADD_DATA_FRAG3 GROUP3_PREFIX "13add_data_fragERNS1_13CacheChange_tEjb"

// Whether the write on this thread may merge its personal GAPs: its change goes to one reader (the
// frame counts the readers each verdict passed; on Fast DDS 3 a routed writer's prefilter counts
// the readers it passes unasked), and it is not a status writer's. Fast DDS's receivers keep the
// destination of an INFO_DST to the end of the datagram (one of GUIDPREFIX_UNKNOWN changes
// nothing: MessageReceiver::proc_Submsg_InfoDST, v2.14.6 and v3.6.2), so that a DATA after a GAP
// of one participant's reader would reach that participant only.
static bool merges_now(void) { return cft_write_passed_now() == 1 && !cft_status_write_now(); }

static void *real_add_gap;

CFT_EXPORT bool cft_add_gap2(void *group, const void *seq, const void *set, const void *reader)
    __asm__(ADD_GAP);
bool cft_add_gap2(void *group, const void *seq, const void *set, const void *reader) {
  add_gap_fn real = (add_gap_fn)cft_guard_real(&real_add_gap, FASTDDS2_SONAME, ADD_GAP);
  if (gap_held(merges_now() ? merge_types2() : NULL, real, __builtin_return_address(0), group,
               seq, set, reader))
    return true;
  return real != NULL && real(group, seq, set, reader);  // else unreachable: Fast DDS called us
}

static void *real_add_gap3;

CFT_EXPORT bool cft_add_gap3(void *group, const void *seq, const void *set, const void *reader)
    __asm__(ADD_GAP3);
bool cft_add_gap3(void *group, const void *seq, const void *set, const void *reader) {
  const void *caller = __builtin_return_address(0);
  add_gap_fn real = (add_gap_fn)cft_guard_real_in_caller(&real_add_gap3, ADD_GAP3, caller);
  if (gap_held(merges_now() ? merge_types3() : NULL, real, caller, group, seq, set, reader))
    return true;
  return real != NULL && real(group, seq, set, reader);  // else unreachable: Fast DDS called us
}

// Whether the HEARTBEAT of a send_heartbeat_nts_ returning to `return_address` is that of a GAP
// held back, and held back with it (`separate`, NULL for never: whether the writer sends each
// reader's DATA apart).
static bool heartbeat_merged(void *self, void *group, bool final, bool liveliness,
                             send_heartbeat_fn real, const void *return_address,
                             bool (*separate)(const void *writer)) {
  struct held *h = awaiting_heartbeat;
  awaiting_heartbeat = NULL;
  if (h == NULL || h->group != group || in_piggyback ||
      caller_of((uintptr_t)return_address) != DELIVER)
    return false;
  if (separate != NULL && separate(self)) {
    // Each reader's DATA goes in a datagram of its own, maybe not this reader's: the GAP goes
    // now, in this reader's, and the HEARTBEAT after it, as Fast DDS sends them.
    held_count--;
    h->add_gap(group, h->seq, h->set, h->reader);
    return false;
  }
  h->writer = self;
  h->send_heartbeat = real;
  h->types->writer_guid(self, h->writer_guid);
  h->final = final;
  h->liveliness = liveliness;
  return true;
}

// Says once that merging stopped, and stops it.
static void merge_stops(void) {
  if (!__atomic_exchange_n(&merge_broken, 1, __ATOMIC_RELAXED))
    cft_say("a personal GAP held back met its DATA with a writer GUID other than its writer's: "
            "GAPs go in datagrams of their own from now on, as Fast DDS sends them");
}

// Before a DATA (or DATA_FRAG) of `change` in `group`: the GAPs held back for it, then one
// HEARTBEAT of its writer (it goes to all the DATA's readers, each GAP's among them). Those held
// for another group or change are stale (an exception, or no locator, left them) and dropped.
static void merge_held(void *group, const void *change) {
  struct held merged[HELD];
  int n = held_count;
  memcpy(merged, held, (size_t)n * sizeof merged[0]);
  held_count = 0;  // before the real members run: they may throw
  awaiting_heartbeat = NULL;
  uint8_t sequence[CFT_SEQUENCE_SIZE], writer_guid[GUID_SIZE];
  merged[0].types->change_ids(change, sequence, writer_guid);
  const struct held *last = NULL;
  for (int i = 0; i < n; i++) {
    const struct held *h = &merged[i];
    if (h->group != group || h->writer == NULL || memcmp(h->base, sequence, sizeof sequence) != 0) {
      count(MERGES_DROPPED);
      continue;
    }
    if (memcmp(h->writer_guid, writer_guid, GUID_SIZE) != 0) {
      count(MERGES_DROPPED);
      merge_stops();
      continue;
    }
    count(GAPS_MERGED);
    h->add_gap(group, h->seq, h->set, h->reader);
    last = h;
  }
  if (last != NULL) {
    last->send_heartbeat(last->writer, 1, group, last->final, last->liveliness);
    merged_group = group;
    merged_writer = last->writer;
  }
}

// Whether the piggyback HEARTBEAT of `self` in `group` would repeat the one merge_held added before
// the DATA it follows: the same writer, the same readers (the DATA's), the same range (the
// change is in the history before either is built). A full history's piggyback follows every DATA.
static bool repeats_merged(void *self, void *group) {
  bool repeats = merged_group == group && merged_writer == self;
  merged_group = merged_writer = NULL;
  return repeats;
}

// Before each DATA or DATA_FRAG: a HEARTBEAT merged for an earlier one is not this one's, and the
// GAPs held for this one go first.
static void before_data(void *group, const void *change) {
  merged_group = merged_writer = NULL;
  if (held_count > 0) merge_held(group, change);
}

typedef bool (*add_data_fn)(void *group, const void *change, bool expects_inline_qos);
typedef bool (*add_data_frag_fn)(void *group, const void *change, uint32_t fragment,
                                 bool expects_inline_qos);
static void *real_add_data, *real_add_data3, *real_add_data_frag, *real_add_data_frag3;

CFT_EXPORT bool cft_add_data2(void *group, const void *change, bool expects_inline_qos)
    __asm__(ADD_DATA);
bool cft_add_data2(void *group, const void *change, bool expects_inline_qos) {
  before_data(group, change);
  add_data_fn real = (add_data_fn)cft_guard_real(&real_add_data, FASTDDS2_SONAME, ADD_DATA);
  return real != NULL && real(group, change, expects_inline_qos);  // else unreachable
}

CFT_EXPORT bool cft_add_data3(void *group, const void *change, bool expects_inline_qos)
    __asm__(ADD_DATA3);
bool cft_add_data3(void *group, const void *change, bool expects_inline_qos) {
  add_data_fn real = (add_data_fn)cft_guard_real_in_caller(&real_add_data3, ADD_DATA3,
                                                           __builtin_return_address(0));
  before_data(group, change);
  return real != NULL && real(group, change, expects_inline_qos);  // else unreachable
}

CFT_EXPORT bool cft_add_data_frag2(void *group, const void *change, uint32_t fragment,
                                   bool expects_inline_qos) __asm__(ADD_DATA_FRAG);
bool cft_add_data_frag2(void *group, const void *change, uint32_t fragment,
                        bool expects_inline_qos) {
  before_data(group, change);
  add_data_frag_fn real =
      (add_data_frag_fn)cft_guard_real(&real_add_data_frag, FASTDDS2_SONAME, ADD_DATA_FRAG);
  return real != NULL && real(group, change, fragment, expects_inline_qos);  // else unreachable
}

CFT_EXPORT bool cft_add_data_frag3(void *group, const void *change, uint32_t fragment,
                                   bool expects_inline_qos) __asm__(ADD_DATA_FRAG3);
bool cft_add_data_frag3(void *group, const void *change, uint32_t fragment,
                        bool expects_inline_qos) {
  add_data_frag_fn real = (add_data_frag_fn)cft_guard_real_in_caller(
      &real_add_data_frag3, ADD_DATA_FRAG3, __builtin_return_address(0));
  before_data(group, change);
  return real != NULL && real(group, change, fragment, expects_inline_qos);  // else unreachable
}

// 0: piggyback HEARTBEATs kept to the DATA's readers; 1: let through to all readers;
// 2: per-write GAPs left for later; 3: GAPs of the other kinds; 4: piggyback HEARTBEATs left out
// (spaced); 5: personal GAPs sent in their DATA's datagram; 6: of those held back, dropped (stale);
// 7: piggyback HEARTBEATs left out after a merged one.
CFT_EXPORT unsigned long cft_guard_heartbeat_count(int which) {
  return which >= 0 && which < COUNTERS ? __atomic_load_n(&counters[which], __ATOMIC_RELAXED) : 0;
}
