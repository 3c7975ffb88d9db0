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
//    as a capture on loopback showed). In a write that judged kept readers only, or whose change
//    goes to one reader (a rate-limited subscriber's, alone on the writer), not a status
//    writer's, the definitions of add_gap and send_heartbeat_nts_ below hold both back on the
//    thread, and add_data (add_data_frag) of the same group, writer and change adds them before its
//    DATA, with one HEARTBEAT after all the GAPs held: INFO_DST scopes each GAP to its reader, the
//    HEARTBEAT goes to the DATA's readers (each GAP's among them), and the flush between sends
//    nothing (RTPSMessageGroup::send skips a message of only its header). CFT_GUARD_MERGE_GAPS=0
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
// The real members are those of the library that called (cft_guard_real_in_caller). N = 16
// clients x 4 goals, depth 10, feedback routed: 0.19x plain's bytes per client and 0.42-0.54x its
// CPU per message, where Fast DDS's own had 1.35x and 2.1-2.3x; the personal GAP and HEARTBEAT
// still come alone before a routed reader's DATA (part 4 reads 2.14's layouts).
//
// These members are exported and called through the PLT. A call from deliver_sample_to_network is
// told by the return address, whose symbol dladdr names once per call site; one from the
// piggyback by send_heartbeat_piggyback_nts_, defined here too (it reaches send_heartbeat_nts_ by a
// tail call, whose return address is its own caller's). They act only where the guard locks the
// Fast DDS 2.14 it knows (cft_guard_knows_fastdds2); elsewhere every call goes through. Part 4
// reads the layouts of the headers the guard was built against (_fastdds_layout.h); without them
// its members are not defined.

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

// Part 4 reads these layouts of the headers the guard was built against; without them (no
// headers, or a layout header made up by a test) its members are not defined.
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

// Fast DDS 3.4.2+'s, with two parameters. A HEARTBEAT it widens goes through select_all_readers_nts
// (below): nothing else of the piggyback's is held back on that family.
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
  widened_now = false;  // read by Fast DDS 2.14's send_heartbeat_nts_ only
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
#if MERGE_LAYOUT_KNOWN
static bool heartbeat_merged(void *self, void *group, bool final, bool liveliness,
                             uintptr_t return_address);
#endif

#if MERGE_LAYOUT_KNOWN
static bool heartbeat_merged(void *self, void *group, bool final, bool liveliness,
                             uintptr_t return_address);
static bool repeats_merged(void *self, void *group);
#endif

CFT_EXPORT void cft_send_heartbeat_nts2(void *self, size_t readers, void *group, bool final,
                                        bool liveliness) __asm__(SEND_HEARTBEAT);
void cft_send_heartbeat_nts2(void *self, size_t readers, void *group, bool final,
                             bool liveliness) {
#if MERGE_LAYOUT_KNOWN
  if (heartbeat_merged(self, group, final, liveliness, (uintptr_t)__builtin_return_address(0)))
    return;
#endif
  long interval = piggyback_ns();
  bool widened = widened_now;
  widened_now = false;
#if MERGE_LAYOUT_KNOWN
  if (!widened && in_piggyback && repeats_merged(self, group)) {
    count(PIGGYBACK_MERGED);
    return;
  }
#endif
  if (interval > 0 && !widened && in_piggyback &&
      cft_write_judged_now() == (CFT_KEPT_READER | CFT_OTHER_READER) && !cft_status_write_now() &&
      !due(piggyback_slots, (uintptr_t)self, interval)) {
    count(PIGGYBACK_SPACED);
    return;
  }
  send_heartbeat_fn real = (send_heartbeat_fn)cft_guard_real(&real_send_heartbeat,
                                                             FASTDDS2_SONAME, SEND_HEARTBEAT);
  if (real != NULL) real(self, readers, group, final, liveliness);  // else unreachable
}

// ---- 4. the personal GAP and HEARTBEAT, in the DATA's datagram (CFT_GUARD_MERGE_GAPS) ----------
// Without the headers' layouts nothing is held back: these members are then not interposed.
#if MERGE_LAYOUT_KNOWN
#define GROUP_PREFIX "_ZN8eprosima8fastrtps4rtps16RTPSMessageGroup"
#define ADD_GAP                                                                                 \
  GROUP_PREFIX "7add_gapERKNS1_16SequenceNumber_tERKNS0_11BitmapRangeIS3_NS1_18SequenceNumberDiff" \
               "ELj256EEERKNS1_6GUID_tE"
#define ADD_DATA GROUP_PREFIX "8add_dataERKNS1_13CacheChange_tEb"
#define ADD_DATA_FRAG GROUP_PREFIX "13add_data_fragERKNS1_13CacheChange_tEjb"
// SecurityManager::cancel_init(), exported only by a Fast DDS built with SECURITY=ON, which
// moves RTPSWriter's members (m_separateSendingEnabled) from the headers' offsets.
#define SECURITY_ONLY_SYMBOL "_ZN8eprosima8fastrtps4rtps8security15SecurityManager11cancel_initEv"
#define GUID_SIZE 16

// CFT_GUARD_MERGE_GAPS: on unless "off" or "0", and only where the guard knows the Fast DDS.
static bool merge_on(void) {
  static int on = -1;  // -1: not read yet
  return cft_guard_part_on(&on, "CFT_GUARD_MERGE_GAPS", true);
}

// Whether `writer` sends each reader's DATA in a datagram of its own (m_separateSendingEnabled).
// In Fast DDS 2.14 only builtin writers do (the discovery server's, security's), which write in no
// frame that judged kept readers. The flag is read where its offset is known: the headers', when
// the loaded library's HAVE_SECURITY, which moves it, is theirs (apt's 2.14.6 beside the wheels'
// headers is not).
static bool separate_sending(const void *writer) {
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
}

// A personal GAP held back on this thread, with the HEARTBEAT that followed it. Those held share
// their group and their change (the set's base): a GAP of another is added after dropping them.
// One per reader with a run that the change goes to (one, for a client's feedback); past HELD a
// GAP goes at once, as in Fast DDS.
#define HELD 4
struct held {
  void *group;                    // the RTPSMessageGroup it was added to
  void *writer;                   // the StatefulWriter whose HEARTBEAT followed; NULL: none yet
  uint8_t writer_guid[GUID_SIZE]; // its GUID, to tell its DATA
  bool final, liveliness;         // that send_heartbeat_nts_'s arguments
  uint8_t seq[CFT_SEQUENCE_SIZE]; // add_gap's arguments: the first sequence number of the run,
  uint8_t set[SNS_SIZE];          // the set, whose base is the change of the DATA that follows,
  uint8_t reader[GUID_SIZE];      // and the reader
};
static __thread struct held held[HELD];
static __thread int held_count;
// The GAP just held back: the send_heartbeat_nts_ that follows it is its own.
static __thread struct held *awaiting_heartbeat;
// The group and writer of the HEARTBEAT that merge_held added before this DATA, if it added one.
static __thread void *merged_group, *merged_writer;

typedef bool (*add_gap_fn)(void *group, const void *seq, const void *set, const void *reader);
static void *real_add_gap;

static add_gap_fn add_gap(void) {
  return (add_gap_fn)cft_guard_real(&real_add_gap, FASTDDS2_SONAME, ADD_GAP);
}

static send_heartbeat_fn send_heartbeat(void) {
  return (send_heartbeat_fn)cft_guard_real(&real_send_heartbeat, FASTDDS2_SONAME, SEND_HEARTBEAT);
}

static void drop_held(void) {
  for (int i = 0; i < held_count; i++) count(MERGES_DROPPED);
  held_count = 0;
  awaiting_heartbeat = NULL;
}

CFT_EXPORT bool cft_add_gap2(void *group, const void *seq, const void *set, const void *reader)
    __asm__(ADD_GAP);
bool cft_add_gap2(void *group, const void *seq, const void *set, const void *reader) {
  if (merge_on() && caller_of((uintptr_t)__builtin_return_address(0)) == DELIVER &&
      (cft_write_judged_now() == CFT_KEPT_READER || cft_write_passed_now() == 1) &&
      !cft_status_write_now()) {
    if (held_count > 0 && (held[0].group != group ||
                           memcmp(held[0].set + SNS_BASE, (const uint8_t *)set + SNS_BASE,
                                  CFT_SEQUENCE_SIZE) != 0))
      drop_held();
    if (held_count < HELD) {
      struct held *h = &held[held_count++];
      h->group = group;
      h->writer = NULL;
      memcpy(h->seq, seq, sizeof h->seq);
      memcpy(h->set, set, sizeof h->set);
      memcpy(h->reader, reader, sizeof h->reader);
      awaiting_heartbeat = h;
      return true;
    }
  }
  add_gap_fn real = add_gap();
  return real != NULL && real(group, seq, set, reader);  // else unreachable: Fast DDS called us
}

// Whether the HEARTBEAT of a send_heartbeat_nts_ returning to `return_address` is that of a GAP
// held back, and held back with it.
static bool heartbeat_merged(void *self, void *group, bool final, bool liveliness,
                             uintptr_t return_address) {
  struct held *h = awaiting_heartbeat;
  awaiting_heartbeat = NULL;
  if (h == NULL || h->group != group || in_piggyback || caller_of(return_address) != DELIVER)
    return false;
  if (separate_sending(self)) {
    // Each reader's DATA goes in a datagram of its own, maybe not this reader's: the GAP goes
    // now, in this reader's, and the HEARTBEAT after it, as Fast DDS sends them.
    held_count--;
    add_gap()(group, h->seq, h->set, h->reader);  // not NULL: Fast DDS called it
    return false;
  }
  h->writer = self;
  memcpy(h->writer_guid, (const uint8_t *)self + SW_GUID, sizeof h->writer_guid);
  h->final = final;
  h->liveliness = liveliness;
  return true;
}

// Before a DATA (or DATA_FRAG) of `change` in `group`: the GAPs held back for it, then one
// HEARTBEAT of its writer (it goes to all the DATA's readers, each GAP's among them). Those held
// for another group or change are stale (an exception, or no locator, left them) and dropped.
static void merge_held(void *group, const uint8_t *change) {
  struct held merged[HELD];
  int n = held_count;
  memcpy(merged, held, (size_t)n * sizeof merged[0]);
  held_count = 0;  // before the real members run: they may throw
  awaiting_heartbeat = NULL;
  const struct held *last = NULL;
  add_gap_fn real = add_gap();  // not NULL: Fast DDS called it
  for (int i = 0; i < n; i++) {
    const struct held *h = &merged[i];
    if (h->group != group || h->writer == NULL ||
        memcmp(h->writer_guid, change + CC_WRITER_GUID, GUID_SIZE) != 0 ||
        memcmp(h->set + SNS_BASE, change + CC_SEQUENCE, CFT_SEQUENCE_SIZE) != 0) {
      count(MERGES_DROPPED);
      continue;
    }
    count(GAPS_MERGED);
    real(group, h->seq, h->set, h->reader);
    last = h;
  }
  if (last != NULL) {
    send_heartbeat()(last->writer, 1, group, last->final, last->liveliness);
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
static void *real_add_data;

CFT_EXPORT bool cft_add_data2(void *group, const void *change, bool expects_inline_qos)
    __asm__(ADD_DATA);
bool cft_add_data2(void *group, const void *change, bool expects_inline_qos) {
  before_data(group, change);
  add_data_fn real = (add_data_fn)cft_guard_real(&real_add_data, FASTDDS2_SONAME, ADD_DATA);
  return real != NULL && real(group, change, expects_inline_qos);  // else unreachable
}

typedef bool (*add_data_frag_fn)(void *group, const void *change, uint32_t fragment,
                                 bool expects_inline_qos);
static void *real_add_data_frag;

CFT_EXPORT bool cft_add_data_frag2(void *group, const void *change, uint32_t fragment,
                                   bool expects_inline_qos) __asm__(ADD_DATA_FRAG);
bool cft_add_data_frag2(void *group, const void *change, uint32_t fragment,
                        bool expects_inline_qos) {
  before_data(group, change);
  add_data_frag_fn real =
      (add_data_frag_fn)cft_guard_real(&real_add_data_frag, FASTDDS2_SONAME, ADD_DATA_FRAG);
  return real != NULL && real(group, change, fragment, expects_inline_qos);  // else unreachable
}
#endif

// 0: piggyback HEARTBEATs kept to the DATA's readers; 1: let through to all readers;
// 2: per-write GAPs left for later; 3: GAPs of the other kinds; 4: piggyback HEARTBEATs left out
// (spaced); 5: personal GAPs sent in their DATA's datagram; 6: of those held back, dropped (stale);
// 7: piggyback HEARTBEATs left out after a merged one.
CFT_EXPORT unsigned long cft_guard_heartbeat_count(int which) {
  return which >= 0 && which < COUNTERS ? __atomic_load_n(&counters[which], __ATOMIC_RELAXED) : 0;
}
