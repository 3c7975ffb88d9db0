// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard: an LD_PRELOAD shim that makes Fast DDS's writer-side content filtering
// race-free in the process that owns the writers (the action server).
//
// The hazard (eProsima/Fast-DDS issue 4878): the discovery thread changes a DataWriterImpl's
// per-reader filter collection (process_reader_filter_info, remove_reader_filter) with no lock
// held, while the thread that writes evaluates those filters (perform_create_new_change ->
// ReaderFilterCollection::update_filter_info -> DDSFilterExpression::evaluate). A filter update or
// a filtered reader going away can therefore free a filter that is being evaluated, and the
// server segfaults.
//
// Inside the Fast DDS library these three DataWriterImpl members are exported and called through
// the PLT, so a definition that is preloaded into the global scope wins. This file defines them
// under their mangled names and serializes, per writer (`this`), the write path with the two
// filter-collection changes, using recursive mutexes striped by `this`. The real definitions are
// found lazily, on first use, in the Fast DDS library that is already loaded:
//   1. dlopen(<known soname>, RTLD_NOLOAD) + dlsym: the only case in which the guard locks;
//   2. otherwise every loaded libfastrtps.so* / libfastdds.so* (dl_iterate_phdr), then
//      dlsym(RTLD_NEXT): the guard calls straight through, without locking, and says once on
//      stderr that it is inactive and why.
// RTLD_NEXT alone does not work: rmw loads Fast DDS with RTLD_LOCAL, outside the global scope.
//
// It never aborts and prints nothing in the normal case (set CFT_GUARD_DEBUG=1 to see what it
// does). It is only ever preloaded, never imported. This file needs no Fast DDS headers; the
// layouts that the other parts read come from those found at build time (_fastdds_layout.h).
// setup.py builds it with the other parts of the guard into one library (_guard.h lists them).

#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <link.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "_guard.h"
#include "_filter_class.h"
#include "_guard_filter.h"
#include "_guard_log.h"
#include "_guard_replies.h"
#include "_guard_status.h"

// ---- public state codes (mirrored in cft_action/guard.py) ---------------------------------------
#define CFT_GUARD_ARMED 0        // preloaded; no Fast DDS resolved yet (none loaded, or not used)
#define CFT_GUARD_ACTIVE 1       // interposing a known Fast DDS: writes and filter changes locked
#define CFT_GUARD_INACTIVE 2     // unknown Fast DDS version, or loaded too late: calls go straight
                                 // through (or, if the real function is missing, fail safely)

// ---- the interposed functions ---------------------------------------------------------------------
// The first three are locked; the fourth, DDSFilterExpression::evaluate (a virtual member, whose
// vtable slot is a relocation against its exported name), is where _guard_filter.c answers
// uuid-only filters without deserializing the sample; the fifth,
// DomainParticipantImpl::find_content_filter_factory, gives the writers the library's own filter
// classes (_filter_class.h); the sixth, DataWriterImpl::is_relevant (IReaderDataFilter's member,
// virtual too: the slots of DataWriterImpl's vtable and of its statistics subclass's are
// R_X86_64_64 relocations against its exported name, no thunk), answers for the readers of those
// classes that _guard_filter.c keeps out of Fast DDS's filter collection, so that no filter
// signature is written for them, and for the readers that an action's reply is not for
// (_guard_replies.c). Only Fast DDS 2.14 has the last three here, but for the fifth, whose mangled
// name is the same in 3.x: there it only calls the real member (cft_find).
enum { FN_PCNC = 0, FN_PRFI = 1, FN_RRF = 2, FN_LOCKED = 3, FN_EVAL = 3, FN_FIND = 4, FN_REL = 5,
       FN_COUNT = 6 };

// Fast DDS 2.x (libfastrtps), verified on 2.14.5 (ROS 2 Jazzy wheels), on 2.14.6 built with
// SECURITY=ON (apt's) and on the 2.14.x head (docs/COMPATIBILITY.md).
#define PCNC2 "_ZN8eprosima7fastdds3dds14DataWriterImpl25perform_create_new_changeENS_8fastrtps4rtps12ChangeKind_tEPvRNS4_11WriteParamsERKNS4_16InstanceHandle_tE"
#define PRFI2 "_ZN8eprosima7fastdds3dds14DataWriterImpl26process_reader_filter_infoERKNS_8fastrtps4rtps6GUID_tERKNS4_15ReaderProxyDataE"
#define RRF2 "_ZN8eprosima7fastdds3dds14DataWriterImpl20remove_reader_filterERKNS_8fastrtps4rtps6GUID_tE"
// The same name in Fast DDS 2 and 3: one definition serves both (cft_find).
#define FIND "_ZN8eprosima7fastdds3dds21DomainParticipantImpl27find_content_filter_factoryEPKc"
#define EVAL2 "_ZNK8eprosima7fastdds3dds12DDSSQLFilter19DDSFilterExpression8evaluateERKNS_8fastrtps4rtps19SerializedPayload_tERKNS1_14IContentFilter16FilterSampleInfoERKNS5_6GUID_tE"
#define REL2 "_ZNK8eprosima7fastdds3dds14DataWriterImpl11is_relevantERKNS_8fastrtps4rtps13CacheChange_tERKNS4_6GUID_tE"

// Fast DDS 3.x (libfastdds), verified on libfastdds.so.3.2 from the ROS 2 Kilted wheels.
#define PCNC3 "_ZN8eprosima7fastdds3dds14DataWriterImpl25perform_create_new_changeENS0_4rtps12ChangeKind_tEPKvRNS3_11WriteParamsERKNS3_16InstanceHandle_tE"
#define PRFI3 "_ZN8eprosima7fastdds3dds14DataWriterImpl26process_reader_filter_infoERKNS0_4rtps6GUID_tERKNS3_28SubscriptionBuiltinTopicDataE"
#define RRF3 "_ZN8eprosima7fastdds3dds14DataWriterImpl20remove_reader_filterERKNS0_4rtps6GUID_tE"

// ReturnCode_t is a class holding one uint32_t in 2.x and an int32_t in 3.x: returned in eax.
typedef uint32_t (*pcnc_fn)(void *self, int kind, const void *data, void *params,
                            const void *handle);
typedef void (*prfi_fn)(void *self, const void *guid, const void *reader_info);
typedef void (*rrf_fn)(void *self, const void *guid);
#define RETCODE_ERROR 1u

// One family per mangling (Fast DDS major version). Its state moves once, from ARMED to ACTIVE
// or INACTIVE, under resolve_lock; `state` is read without the lock (acquire), and everything
// else is written before the release store and never changed afterwards.
struct family {
  const char *label;
  const char *known_soname;   // the one version whose ABI and behaviour were checked
  const char *prefix;         // basename prefix of any library of this family
  const char *names[FN_COUNT];
  void *real[FN_COUNT];
  int state;
  pthread_mutex_t resolve_lock;
  char reason[512];
};

static struct family families[] = {
  {"Fast DDS 2", "libfastrtps.so.2.14", "libfastrtps.so", {PCNC2, PRFI2, RRF2, EVAL2, FIND, REL2},
   {0}, 0, PTHREAD_MUTEX_INITIALIZER, ""},
  {"Fast DDS 3", "libfastdds.so.3.2", "libfastdds.so", {PCNC3, PRFI3, RRF3, NULL, FIND, NULL}, {0},
   0, PTHREAD_MUTEX_INITIALIZER, ""},
};
#define N_FAMILIES ((int)(sizeof(families) / sizeof(families[0])))

static unsigned long call_counts[FN_LOCKED];
static unsigned long filter_class_lookups, filter_class_filters;  // cft_guard_filter_class_count
static unsigned long degraded_count;     // nested acquisitions that gave up (see lock_writer)
static int loaded_after_fastdds;         // set by the constructor
static char late_reason[512];

// ---- the locks --------------------------------------------------------------------------------------
// Recursive, because a writer's filter code may re-enter another interposed member of the same
// writer on the same thread. 256 stripes keep unrelated writers mostly apart.
#define STRIPES 256
static pthread_mutex_t stripes[STRIPES] = {[0 ... STRIPES - 1] = PTHREAD_RECURSIVE_MUTEX_INITIALIZER_NP};

// The stripe this thread already holds (outermost), and how deeply it holds it.
static __thread pthread_mutex_t *held_stripe;
static __thread int held_depth;

static pthread_mutex_t *stripe_for(const void *writer) {
  uint64_t h = ((uint64_t)(uintptr_t)writer >> 4) * 0x9E3779B97F4A7C15ull;
  return &stripes[h >> 56];  // top 8 bits: STRIPES == 256
}

// Returns the mutex taken, or NULL when it went on without one (see below).
static pthread_mutex_t *lock_writer(const void *writer) {
  pthread_mutex_t *m = stripe_for(writer);
  if (held_depth == 0 || held_stripe == m) {
    pthread_mutex_lock(m);
  } else {
    // A write nested in another writer's write on this thread (e.g. Fast DDS statistics writers
    // publishing from inside a user write) that maps to another stripe. Two such threads with
    // crossed stripes would deadlock, so a nested acquisition waits at most ~50 ms and then goes
    // on unlocked (as Fast DDS itself would). Outer acquisitions always block normally, so no
    // cycle of guard locks can form.
    int got = 0;
    for (int i = 0; i < 1000; i++) {
      if (pthread_mutex_trylock(m) == 0) { got = 1; break; }
      struct timespec ts = {0, 50000};
      nanosleep(&ts, NULL);
    }
    if (!got) {
      if (__atomic_fetch_add(&degraded_count, 1, __ATOMIC_RELAXED) == 0 && cft_debug_enabled())
        cft_say("a nested write went on without its lock after 50 ms (deadlock avoidance)");
      return NULL;
    }
    held_depth++;
    return m;  // held_stripe stays the outer one
  }
  if (held_depth++ == 0) held_stripe = m;
  return m;
}

static void unlock_writer(pthread_mutex_t *m) {
  if (m == NULL) return;
  if (--held_depth == 0) held_stripe = NULL;
  pthread_mutex_unlock(m);
}

// Holds the writer's stripe until the end of the enclosing block, however it is left: built with
// -fexceptions, a C++ exception unwinding through the wrapper runs the cleanup too. Without it, a
// throwing write would leave the stripe locked and hang the next thread that needs it (the
// discovery thread, and with it participant shutdown).
static void unlock_at_scope_end(pthread_mutex_t **m) { unlock_writer(*m); }
#define LOCK_WRITER_IN_SCOPE(writer) \
  pthread_mutex_t *scoped_lock_ __attribute__((cleanup(unlock_at_scope_end))) = lock_writer(writer)

// ---- finding the real definitions -------------------------------------------------------------------
static const char *base_name(const char *path) {
  const char *slash = strrchr(path, '/');
  return slash ? slash + 1 : path;
}

// Loaded objects whose basename starts with a Fast DDS prefix, collected by dl_iterate_phdr.
#define MAX_FOUND 8
struct loaded_list {
  int count;
  char paths[MAX_FOUND][512];
};

static int collect_cb(struct dl_phdr_info *info, size_t size, void *data) {
  (void)size;
  struct loaded_list *list = data;
  const char *name = info->dlpi_name;
  if (name == NULL || name[0] == '\0' || list->count >= MAX_FOUND) return 0;
  const char *base = base_name(name);
  for (int i = 0; i < N_FAMILIES; i++) {
    if (strncmp(base, families[i].prefix, strlen(families[i].prefix)) == 0) {
      snprintf(list->paths[list->count++], sizeof list->paths[0], "%s", name);
      break;
    }
  }
  return 0;
}

static void loaded_fastdds(struct loaded_list *list) {
  list->count = 0;
  dl_iterate_phdr(collect_cb, list);  // dlopen is called only after it returns
}

static int family_of_path(const char *path) {
  const char *base = base_name(path);
  for (int i = 0; i < N_FAMILIES; i++)
    if (strncmp(base, families[i].prefix, strlen(families[i].prefix)) == 0) return i;
  return -1;
}

static void *our_definition(int fam, int fn);

// Looks up all of the family's names in `handle`. Returns how many of the locked members were
// found; a result equal to our own definition (which could only come from the global scope) is
// rejected.
static int lookup_all(struct family *f, int fam, void *handle, void *out[FN_COUNT]) {
  int found = 0;
  for (int i = 0; i < FN_COUNT; i++) {
    void *p = f->names[i] != NULL ? dlsym(handle, f->names[i]) : NULL;
    if (p == our_definition(fam, i)) p = NULL;
    out[i] = p;
    if (i < FN_LOCKED) found += p != NULL;
  }
  return found;
}

static const char *object_of(void *addr, char *buf, size_t len) {
  Dl_info info;
  if (addr != NULL && dladdr(addr, &info) && info.dli_fname != NULL)
    snprintf(buf, len, "%s", info.dli_fname);
  else
    snprintf(buf, len, "?");
  return buf;
}

// Sets the family's final state. Called with resolve_lock held and state == ARMED.
// With from_call == 0 (a probe from cft_guard_state) it leaves the state ARMED when no library of
// this family is loaded yet; from an interposed call it always decides.
static void resolve_locked(int fam, int from_call) {
  struct family *f = &families[fam];
  void *real[FN_COUNT] = {0};
  char where[512];
  int state = CFT_GUARD_INACTIVE;

  void *handle = dlopen(f->known_soname, RTLD_LAZY | RTLD_NOLOAD);
  if (handle != NULL) {
    int found = lookup_all(f, fam, handle, real);
    // The handle is kept on purpose: the cached pointers must not outlive the library.
    if (found == FN_LOCKED && !loaded_after_fastdds) {
      state = CFT_GUARD_ACTIVE;
      snprintf(f->reason, sizeof f->reason, "active: %s (%s)", f->known_soname,
               object_of(real[FN_PCNC], where, sizeof where));
    } else if (found == FN_LOCKED) {
      snprintf(f->reason, sizeof f->reason, "inactive: %.480s", late_reason);
    } else {
      snprintf(f->reason, sizeof f->reason,
               "inactive: %s is loaded but lacks %d of the %d DataWriterImpl members this guard "
               "wraps; not locking", f->known_soname, FN_LOCKED - found, FN_LOCKED);
    }
  } else {
    // Not the known version. Find the real definitions anyway, to call straight through.
    struct loaded_list list;
    loaded_fastdds(&list);
    const char *seen = NULL;
    for (int i = 0; i < list.count; i++) {
      if (family_of_path(list.paths[i]) != fam) continue;
      seen = list.paths[i];
      void *h = dlopen(list.paths[i], RTLD_LAZY | RTLD_NOLOAD);
      if (h == NULL) continue;
      void *candidate[FN_COUNT];
      if (lookup_all(f, fam, h, candidate) > 0) {
        memcpy(real, candidate, sizeof real);
        break;  // keep h: the pointers refer into it
      }
      dlclose(h);
    }
    for (int i = 0; i < FN_COUNT; i++) {
      if (real[i] != NULL || f->names[i] == NULL) continue;
      void *p = dlsym(RTLD_NEXT, f->names[i]);
      real[i] = p == our_definition(fam, i) ? NULL : p;
    }
    int found = (real[0] != NULL) + (real[1] != NULL) + (real[2] != NULL);
    if (found == 0 && seen == NULL && !from_call) return;  // nothing of this family loaded yet
    if (found > 0) {
      snprintf(f->reason, sizeof f->reason,
               "inactive: %s is not a Fast DDS version this guard knows (it knows %s); calling "
               "it directly, without locking", object_of(real[real[0] ? 0 : real[1] ? 1 : 2],
                                                         where, sizeof where), f->known_soname);
    } else if (from_call) {
      snprintf(f->reason, sizeof f->reason,
               "inactive: cannot find the real %s DataWriterImpl members (loaded: %s); writes "
               "fail and filter changes are skipped", f->label, seen ? seen : "none");
    } else {
      snprintf(f->reason, sizeof f->reason,
               "inactive: %s does not export the DataWriterImpl members this guard wraps (not a "
               "Fast DDS version it knows); nothing is locked", seen);
    }
  }

  memcpy(f->real, real, sizeof real);
  if (state == CFT_GUARD_ACTIVE && real[FN_EVAL] != NULL)
    cft_filter_enable((cft_evaluate_fn)real[FN_EVAL],
                      real[FN_REL] != NULL ? our_definition(fam, FN_REL) : NULL);
  __atomic_store_n(&f->state, state, __ATOMIC_RELEASE);
  if (state != CFT_GUARD_ACTIVE)
    cft_say("%s", f->reason);  // the one line the user needs; printed once per family
  else if (cft_debug_enabled())
    cft_say("%s", f->reason);
}

static void resolve(int fam, int from_call) {
  struct family *f = &families[fam];
  pthread_mutex_lock(&f->resolve_lock);
  if (__atomic_load_n(&f->state, __ATOMIC_ACQUIRE) == CFT_GUARD_ARMED) resolve_locked(fam, from_call);
  pthread_mutex_unlock(&f->resolve_lock);
}

static inline struct family *ready(int fam) {
  struct family *f = &families[fam];
  if (__builtin_expect(__atomic_load_n(&f->state, __ATOMIC_ACQUIRE) == CFT_GUARD_ARMED, 0))
    resolve(fam, 1);
  return f;
}

void *cft_guard_real(void **cache, const char *soname, const char *name) {
  void *p = __atomic_load_n(cache, __ATOMIC_ACQUIRE);
  if (p != NULL) return p;
  void *handle = dlopen(soname, RTLD_LAZY | RTLD_NOLOAD);
  p = handle != NULL ? dlsym(handle, name) : NULL;
  if (p == NULL) p = dlsym(RTLD_NEXT, name);
  __atomic_store_n(cache, p, __ATOMIC_RELEASE);
  return p;
}

// Asked from the guard's other parts, also in a process of another family: family 0 is decided
// only once its library is loaded (a probe, as cft_guard_state's), never declared missing.
int cft_guard_knows_fastdds2(void) {
  if (__atomic_load_n(&families[0].state, __ATOMIC_ACQUIRE) == CFT_GUARD_ARMED) resolve(0, 0);
  return __atomic_load_n(&families[0].state, __ATOMIC_ACQUIRE) == CFT_GUARD_ACTIVE;
}

// The family of the Fast DDS loaded in this process (the first found), for a member whose name
// both families share; 0 when none is found.
static int loaded_family(void) {
  static int cached = -1;
  int fam = __atomic_load_n(&cached, __ATOMIC_ACQUIRE);
  if (fam >= 0) return fam;
  struct loaded_list list;
  loaded_fastdds(&list);
  fam = list.count > 0 ? family_of_path(list.paths[0]) : -1;
  if (fam < 0) return 0;
  __atomic_store_n(&cached, fam, __ATOMIC_RELEASE);
  return fam;
}

bool cft_guard_part_on(int *cache, const char *env, bool usable) {
  int v = __atomic_load_n(cache, __ATOMIC_RELAXED);
  if (v >= 0) return v;
  const char *text = getenv(env);
  v = !(text != NULL && (strcmp(text, "off") == 0 || strcmp(text, "0") == 0)) && usable &&
      cft_guard_knows_fastdds2();
  __atomic_store_n(cache, v, __ATOMIC_RELAXED);
  return v;
}

long cft_guard_ms_to_ns(const char *text, long min_ms, long max_ms) {
  char *end;
  long ms = strtol(text, &end, 10);
  return end == text || *end != '\0' || ms < min_ms || ms > max_ms ? -1 : ms * 1000000L;
}

long cft_guard_env_ms(long *cache, const char *env, long fallback_ms, long min_ms, long max_ms) {
  long v = __atomic_load_n(cache, __ATOMIC_RELAXED);
  if (v >= 0) return v;
  const char *text = getenv(env);
  if (text == NULL || text[0] == '\0') {
    v = fallback_ms * 1000000L;
  } else if (strcmp(text, "off") == 0) {
    v = 0;
  } else if ((v = cft_guard_ms_to_ns(text, min_ms, max_ms)) < 0) {
    cft_say("%s=%.40s is not off or a number of ms from %ld to %ld; using %ld", env, text, min_ms,
            max_ms, fallback_ms);
    v = fallback_ms * 1000000L;
  }
  __atomic_store_n(cache, v, __ATOMIC_RELAXED);
  return v;
}

static void missing(struct family *f, int fn) {
  static int told;
  if (!__atomic_exchange_n(&told, 1, __ATOMIC_RELAXED))
    cft_say("no real definition of %s; %s", f->names[fn], f->reason);
}

// ---- the interposed definitions ---------------------------------------------------------------------
// Restores the thread's filtering writer when the enclosing block is left, however it is left.
static void restore_filtering_writer(const void **saved) { cft_filtering_writer = *saved; }
#define FILTERING_WRITER_IN_SCOPE(writer)                                                        \
  const void *saved_writer_ __attribute__((cleanup(restore_filtering_writer))) =                \
      cft_filtering_writer;                                                                     \
  cft_filtering_writer = (writer)

// Opens _guard_status.c's frame of the write for the enclosing block (`open`: the family has it),
// and closes it however the block is left.
static void close_status_frame(struct cft_status_frame **frame) {
  if (*frame != NULL) cft_status_frame_close(*frame);
}
#define STATUS_FRAME_IN_SCOPE(open)                                                              \
  struct cft_status_frame status_frame_;                                                         \
  struct cft_status_frame *status_frame_open_ __attribute__((cleanup(close_status_frame))) =    \
      (open) ? &status_frame_ : NULL;                                                            \
  if (status_frame_open_ != NULL) cft_status_frame_open(status_frame_open_)

// The writer whose process_reader_filter_info runs on this thread, when the guard keeps the
// writer's filters of the library's classes (Fast DDS 2.14): a filter created now is that
// writer's (guard_created).
static __thread const void *matching_writer;
static void restore_matching_writer(const void **saved) { matching_writer = *saved; }
#define MATCHING_WRITER_IN_SCOPE(writer)                                                         \
  const void *saved_matching_ __attribute__((cleanup(restore_matching_writer))) =               \
      matching_writer;                                                                          \
  matching_writer = (writer)

// Opens _guard_filter.c's claim on a reader of the library's classes for the enclosing block (the
// real process_reader_filter_info), and closes it however the block is left.
static void close_claim(bool *open) {
  if (*open) cft_filter_claim_end();
}
#define CLAIM_IN_SCOPE(may, writer, guid, info)                                                  \
  bool claim_open_ __attribute__((cleanup(close_claim))) =                                      \
      (may) && cft_filter_claim_begin(writer, guid, info)

// FILTERS: 1 where the uuid verdicts of _guard_filter.c know the family's layouts (Fast DDS 2.14).
#define DEFINE_WRAPPERS(SUFFIX, FAM, FILTERS, PCNC, PRFI, RRF)                                  \
  CFT_EXPORT uint32_t cft_pcnc##SUFFIX(void *self, int kind, const void *data, void *params,    \
                                       const void *handle) __asm__(PCNC);                       \
  CFT_EXPORT void cft_prfi##SUFFIX(void *self, const void *guid, const void *info) __asm__(PRFI); \
  CFT_EXPORT void cft_rrf##SUFFIX(void *self, const void *guid) __asm__(RRF);                   \
                                                                                                \
  uint32_t cft_pcnc##SUFFIX(void *self, int kind, const void *data, void *params,               \
                            const void *handle) {                                               \
    struct family *f = ready(FAM);                                                              \
    __atomic_fetch_add(&call_counts[FN_PCNC], 1, __ATOMIC_RELAXED);                             \
    pcnc_fn real = (pcnc_fn)f->real[FN_PCNC];                                                   \
    if (real == NULL) { missing(f, FN_PCNC); return RETCODE_ERROR; }                            \
    if (f->state != CFT_GUARD_ACTIVE) return real(self, kind, data, params, handle);            \
    LOCK_WRITER_IN_SCOPE(self);                                                                 \
    FILTERING_WRITER_IN_SCOPE(FILTERS && scoped_lock_ != NULL ? self : NULL);                   \
    STATUS_FRAME_IN_SCOPE(FILTERS);                                                             \
    return real(self, kind, data, params, handle);                                              \
  }                                                                                             \
  void cft_prfi##SUFFIX(void *self, const void *guid, const void *info) {                       \
    struct family *f = ready(FAM);                                                              \
    __atomic_fetch_add(&call_counts[FN_PRFI], 1, __ATOMIC_RELAXED);                             \
    prfi_fn real = (prfi_fn)f->real[FN_PRFI];                                                   \
    if (real == NULL) { missing(f, FN_PRFI); return; }                                          \
    if (f->state != CFT_GUARD_ACTIVE) { real(self, guid, info); return; }                       \
    LOCK_WRITER_IN_SCOPE(self);                                                                 \
    CLAIM_IN_SCOPE(FILTERS && scoped_lock_ != NULL, self, guid, info);                          \
    MATCHING_WRITER_IN_SCOPE(FILTERS ? self : NULL);                                            \
    real(self, guid, info);                                                                     \
    if (FILTERS && scoped_lock_ != NULL) cft_filter_reader_changed(self, guid, info);           \
    else if (FILTERS) cft_filter_reader_dropped(self, guid);                                    \
    if (FILTERS) cft_replies_reader_matched(self, guid, info);                                  \
  }                                                                                             \
  void cft_rrf##SUFFIX(void *self, const void *guid) {                                          \
    struct family *f = ready(FAM);                                                              \
    __atomic_fetch_add(&call_counts[FN_RRF], 1, __ATOMIC_RELAXED);                              \
    rrf_fn real = (rrf_fn)f->real[FN_RRF];                                                      \
    if (real == NULL) { missing(f, FN_RRF); return; }                                           \
    if (f->state != CFT_GUARD_ACTIVE) { real(self, guid); return; }                             \
    LOCK_WRITER_IN_SCOPE(self);                                                                 \
    real(self, guid);                                                                           \
    if (FILTERS) cft_filter_reader_dropped(self, guid);                                         \
  }

DEFINE_WRAPPERS(2, 0, 1, PCNC2, PRFI2, RRF2)
DEFINE_WRAPPERS(3, 1, 0, PCNC3, PRFI3, RRF3)

// DDSFilterExpression::evaluate of Fast DDS 2.x: a uuid verdict when _guard_filter.c has one for
// this writer and reader, else the real evaluation.
CFT_EXPORT bool cft_evaluate2(const void *self, const void *payload, const void *sample_info,
                              const void *reader_guid) __asm__(EVAL2);
bool cft_evaluate2(const void *self, const void *payload, const void *sample_info,
                   const void *reader_guid) {
  struct family *f = ready(0);
  cft_evaluate_fn real = (cft_evaluate_fn)f->real[FN_EVAL];
  if (real == NULL) {
    // Only Fast DDS calls this, through a vtable it filled itself, so it is loaded; a missing
    // real definition means it is not one this guard can name. Deliver, as a filter that could
    // not be evaluated: rclpy's own UUID check still guards every feedback callback.
    missing(f, FN_EVAL);
    return true;
  }
  if (f->state == CFT_GUARD_ACTIVE) return cft_filter_evaluate(self, payload, sample_info, reader_guid);
  return real(self, payload, sample_info, reader_guid);
}

// DataWriterImpl::is_relevant of Fast DDS 2.x, `this` being the DataWriterImpl (IReaderDataFilter is
// its primary base): the verdict for a reader that _guard_filter.c keeps, else Fast DDS's.
typedef bool (*relevant_fn)(const void *self, const void *change, const void *reader_guid);
CFT_EXPORT bool cft_is_relevant2(const void *self, const void *change, const void *reader_guid)
    __asm__(REL2);
bool cft_is_relevant2(const void *self, const void *change, const void *reader_guid) {
  struct family *f = ready(0);
  bool active = f->state == CFT_GUARD_ACTIVE;
  if (active) {
    int verdict = cft_filter_relevance(self, change, reader_guid);
    cft_write_judged(verdict >= 0 ? CFT_KEPT_READER : CFT_OTHER_READER);
    if (verdict >= 0) return cft_write_passes(verdict == 1);
    if (cft_replies_relevance(change, reader_guid) == 0) return false;
  }
  relevant_fn real = (relevant_fn)f->real[FN_REL];
  if (real == NULL) {
    // Called through a vtable Fast DDS filled, so it is loaded but not one the guard can name:
    // deliver, as Fast DDS does for a reader it has no filter for.
    missing(f, FN_REL);
    return true;
  }
  bool passed = real(self, change, reader_guid);
  return active ? cft_write_passes(passed) : passed;
}

// DataWriterImpl::guid() of Fast DDS 2.x: a reference to the writer's GUID_t (16 bytes).
#define WRITER_GUID2 "_ZNK8eprosima7fastdds3dds14DataWriterImpl4guidEv"
typedef const uint8_t *(*writer_guid_fn)(const void *self);
static void *real_writer_guid;

// The guard's filters of the library's classes: every one may be created, and each is counted.
// One created for a writer is listed under the writer's GUID (cft_guard_closed_readers).
static bool guard_may_create(void) { return true; }
static void guard_created(void *filter) {
  __atomic_fetch_add(&filter_class_filters, 1, __ATOMIC_RELAXED);
  if (matching_writer == NULL) return;
  writer_guid_fn guid =
      (writer_guid_fn)cft_guard_real(&real_writer_guid, families[0].known_soname, WRITER_GUID2);
  if (guid != NULL) cft_filter_at_writer(filter, guid(matching_writer));
}

// How many of the readers matched by this process's writer whose GUID is `writer_guid` (16 bytes)
// a sample written now would not reach because of a filter of the library's classes (a rate
// window that is closed, a poll with no messages left); -1 where the guard does not keep the
// writers' filters (not active on Fast DDS 2.14).
CFT_EXPORT int cft_guard_closed_readers(const uint8_t *writer_guid) {
  if (!cft_guard_knows_fastdds2()) return -1;
  return cft_filter_class_closed(writer_guid);
}
static const struct cft_filter_class_owner guard_owner = {guard_may_create, guard_created};

// The writers of a guarded server filter for readers of the library's classes: every filter change
// is locked here. Unguarded (an unknown Fast DDS), the classes stay unknown to the server, which
// then sends such readers everything, as to plain ones.
CFT_EXPORT void *cft_find(void *self, const char *class_name) __asm__(FIND);
void *cft_find(void *self, const char *class_name) {
  int fam = loaded_family();
  struct family *f = ready(fam);
  // A writer asking for the class of a reader that _guard_filter.c keeps (one of the library's
  // classes, or the status class of _guard_status.c, which no factory here answers): no factory,
  // so that Fast DDS keeps no filter, and no signature, for it.
  // Fast DDS 3: only the real member (the library's classes are Fast DDS 2.14's).
  bool active = fam == 0 && f->state == CFT_GUARD_ACTIVE;
  if (active && cft_filter_claimed(class_name)) return NULL;
  void *ours = active ? cft_filter_factory_for(class_name, &guard_owner) : NULL;
  if (ours != NULL) {
    __atomic_fetch_add(&filter_class_lookups, 1, __ATOMIC_RELAXED);
    return ours;
  }
  typedef void *(*find_fn)(void *, const char *);
  find_fn real = (find_fn)f->real[FN_FIND];
  if (real == NULL) {
    missing(f, FN_FIND);
    return NULL;
  }
  return real(self, class_name);
}


// 0: lookups of the library's filter classes answered; 1: filters of those classes created (for
// the writers and readers of this process); 2: their verdicts; 3: filters created or changed.
CFT_EXPORT unsigned long cft_guard_filter_class_count(int which) {
  if (which == 2) return cft_filter_class_total_verdicts();
  if (which == 3) return cft_filter_class_total_changes();
  return __atomic_load_n(which == 0 ? &filter_class_lookups : &filter_class_filters,
                         __ATOMIC_RELAXED);
}

static void *our_definition(int fam, int fn) {
  static void *const ours[][FN_COUNT] = {
    {(void *)cft_pcnc2, (void *)cft_prfi2, (void *)cft_rrf2, (void *)cft_evaluate2,
     (void *)cft_find, (void *)cft_is_relevant2},
    {(void *)cft_pcnc3, (void *)cft_prfi3, (void *)cft_rrf3, NULL, (void *)cft_find, NULL},
  };
  return ours[fam][fn];
}

// ---- load time ---------------------------------------------------------------------------------------
// A guard that arrives after Fast DDS (dlopen'ed late instead of preloaded) cannot be sure that
// Fast DDS's calls reach it, so it never claims to be active then.
// dl_iterate_phdr lists objects in load order. A Fast DDS that comes after the guard (a DT_NEEDED of
// the executable is mapped after LD_PRELOAD) is fine; one that comes before it is not.
struct order_scan {
  int self_seen;
  struct loaded_list before;
};

static int order_cb(struct dl_phdr_info *info, size_t size, void *data) {
  struct order_scan *scan = data;
  (void)size;
  if (scan->self_seen) return 1;
  uintptr_t self = (uintptr_t)&families;
  for (int i = 0; i < info->dlpi_phnum; i++) {
    const ElfW(Phdr) *ph = &info->dlpi_phdr[i];
    uintptr_t start = info->dlpi_addr + ph->p_vaddr;
    if (ph->p_type == PT_LOAD && self >= start && self < start + ph->p_memsz) {
      scan->self_seen = 1;
      return 1;
    }
  }
  return collect_cb(info, size, &scan->before);
}

__attribute__((constructor)) static void cft_guard_loaded(void) {
  struct order_scan scan = {0};
  dl_iterate_phdr(order_cb, &scan);
  struct loaded_list list = scan.before;
  if (list.count > 0) {
    loaded_after_fastdds = 1;
    snprintf(late_reason, sizeof late_reason,
             "the guard was loaded after Fast DDS (%.400s); preload it with LD_PRELOAD instead",
             list.paths[0]);
    if (cft_debug_enabled()) cft_say("%s", late_reason);
  } else if (cft_debug_enabled()) {
    cft_say("loaded; waiting for Fast DDS");
  }
}

// ---- the C API, for ctypes -----------------------------------------------------------------------------
// Resolves every family whose library is loaded by now, then reports the overall state:
// INACTIVE if the guard was loaded too late, if any family is inactive, or if a loaded
// libfastrtps/libfastdds is not one this guard knows; otherwise ACTIVE when at least one family
// is active, else ARMED.
CFT_EXPORT int cft_guard_state(void) {
  for (int i = 0; i < N_FAMILIES; i++)
    if (__atomic_load_n(&families[i].state, __ATOMIC_ACQUIRE) == CFT_GUARD_ARMED) resolve(i, 0);
  if (loaded_after_fastdds) return CFT_GUARD_INACTIVE;
  int any_active = 0;
  for (int i = 0; i < N_FAMILIES; i++) {
    int s = __atomic_load_n(&families[i].state, __ATOMIC_ACQUIRE);
    if (s == CFT_GUARD_INACTIVE) return CFT_GUARD_INACTIVE;
    any_active |= s == CFT_GUARD_ACTIVE;
  }
  return any_active ? CFT_GUARD_ACTIVE : CFT_GUARD_ARMED;
}

// 1 when the guard is loaded and either interposing a known Fast DDS or waiting for one to load;
// 0 when it is inactive (see cft_guard_reason).
CFT_EXPORT int cft_guard_is_active(void) { return cft_guard_state() != CFT_GUARD_INACTIVE; }

// Human-readable reason for the current state. The returned string is never freed or changed.
CFT_EXPORT const char *cft_guard_reason(void) {
  int state = cft_guard_state();
  if (loaded_after_fastdds) return late_reason;
  const char *active = NULL;
  for (int i = 0; i < N_FAMILIES; i++) {
    int s = __atomic_load_n(&families[i].state, __ATOMIC_ACQUIRE);
    if (s == CFT_GUARD_INACTIVE) return families[i].reason;
    if (s == CFT_GUARD_ACTIVE && active == NULL) active = families[i].reason;
  }
  if (state == CFT_GUARD_ACTIVE && active != NULL) return active;
  return "armed: no Fast DDS loaded yet; it will be interposed when it is";
}

// How often each interposed member was called: 0 perform_create_new_change,
// 1 process_reader_filter_info, 2 remove_reader_filter, 3 nested writes that went on unlocked.
CFT_EXPORT unsigned long cft_guard_call_count(int which) {
  if (which >= 0 && which < FN_LOCKED) return __atomic_load_n(&call_counts[which], __ATOMIC_RELAXED);
  if (which == FN_LOCKED) return __atomic_load_n(&degraded_count, __ATOMIC_RELAXED);
  return 0;
}
