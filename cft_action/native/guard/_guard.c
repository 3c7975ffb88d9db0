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
// filter-collection changes, using recursive mutexes striped by `this`. Where the real definitions
// are, and whether the loaded Fast DDS is one the guard locks, is _guard_families.c's.
//
// It never aborts and prints nothing in the normal case (set CFT_GUARD_DEBUG=1 to see what it
// does). It is only ever preloaded, never imported. This file needs no Fast DDS headers; the
// layouts that the other parts read come from those found at build time (_fastdds_layout.h).

#define _GNU_SOURCE
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "_filter_class.h"
#include "_guard_families.h"
#include "_guard_filter.h"
#include "_guard_log.h"
#include "_guard_replies.h"
#include "_guard_status.h"

// ReturnCode_t is a class holding one uint32_t in 2.x and an int32_t in 3.x: returned in eax.
typedef uint32_t (*pcnc_fn)(void *self, int kind, const void *data, void *params,
                            const void *handle);
typedef void (*prfi_fn)(void *self, const void *guid, const void *reader_info);
typedef void (*rrf_fn)(void *self, const void *guid);
#define RETCODE_ERROR 1u

static unsigned long call_counts[FN_LOCKED];
static unsigned long filter_class_lookups, filter_class_filters;  // cft_guard_filter_class_count
static unsigned long degraded_count;     // nested acquisitions that gave up (see lock_writer)

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

// ---- the interposed definitions ---------------------------------------------------------------------
// Restores the thread's filtering writer when the enclosing block is left, however it is left.
static void restore_filtering_writer(const void **saved) { cft_filtering_writer = *saved; }
#define FILTERING_WRITER_IN_SCOPE(writer)                                                        \
  const void *saved_writer_ __attribute__((cleanup(restore_filtering_writer))) =                \
      cft_filtering_writer;                                                                     \
  cft_filtering_writer = (writer)

// Opens _guard_status.c's frame of the write for the enclosing block, and closes it however the
// block is left. Every family has it: on Fast DDS 3 the verdicts of routed readers mark it
// (_guard_feedback.c), for _guard_heartbeats.c.
static void close_status_frame(struct cft_status_frame *frame) { cft_status_frame_close(frame); }
#define STATUS_FRAME_IN_SCOPE()                                                                  \
  struct cft_status_frame status_frame_ __attribute__((cleanup(close_status_frame)));           \
  cft_status_frame_open(&status_frame_)

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

CFT_EXPORT bool cft_is_relevant2(const void *self, const void *change, const void *reader_guid)
    __asm__(REL2);

// The family, decided, and, once Fast DDS 2.14's is active, _guard_filter.c told where the real
// evaluate and the guard's is_relevant are (before any call of this file goes into it).
static pthread_once_t filter_once = PTHREAD_ONCE_INIT;
static void enable_filter(void) {
  struct family *f = cft_family_ready(0);
  if (f->real[FN_EVAL] != NULL)
    cft_filter_enable((cft_evaluate_fn)f->real[FN_EVAL],
                      f->real[FN_REL] != NULL ? (const void *)cft_is_relevant2 : NULL);
}
static struct family *ready(int fam) {
  struct family *f = cft_family_ready(fam);
  if (fam == 0 && __atomic_load_n(&f->state, __ATOMIC_ACQUIRE) == CFT_GUARD_ACTIVE)
    pthread_once(&filter_once, enable_filter);
  return f;
}

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
    if (real == NULL) { cft_family_missing(f, FN_PCNC); return RETCODE_ERROR; }                 \
    if (f->state != CFT_GUARD_ACTIVE) return real(self, kind, data, params, handle);            \
    LOCK_WRITER_IN_SCOPE(self);                                                                 \
    FILTERING_WRITER_IN_SCOPE(FILTERS && scoped_lock_ != NULL ? self : NULL);                   \
    STATUS_FRAME_IN_SCOPE();                                                                    \
    return real(self, kind, data, params, handle);                                              \
  }                                                                                             \
  void cft_prfi##SUFFIX(void *self, const void *guid, const void *info) {                       \
    struct family *f = ready(FAM);                                                              \
    __atomic_fetch_add(&call_counts[FN_PRFI], 1, __ATOMIC_RELAXED);                             \
    prfi_fn real = (prfi_fn)f->real[FN_PRFI];                                                   \
    if (real == NULL) { cft_family_missing(f, FN_PRFI); return; }                               \
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
    if (real == NULL) { cft_family_missing(f, FN_RRF); return; }                                \
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
    cft_family_missing(f, FN_EVAL);
    return true;
  }
  if (f->state == CFT_GUARD_ACTIVE) return cft_filter_evaluate(self, payload, sample_info, reader_guid);
  return real(self, payload, sample_info, reader_guid);
}

// DataWriterImpl::is_relevant of Fast DDS 2.x, `this` being the DataWriterImpl (IReaderDataFilter is
// its primary base): the verdict for a reader that _guard_filter.c keeps, else Fast DDS's.
typedef bool (*relevant_fn)(const void *self, const void *change, const void *reader_guid);
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
    cft_family_missing(f, FN_REL);
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
      (writer_guid_fn)cft_guard_real(&real_writer_guid, cft_family_ready(0)->known_sonames[0],
                                     WRITER_GUID2);
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
static const struct cft_filter_class_owner guard_owner = {
    .may_create = guard_may_create, .created = guard_created, .refused = cft_filter_refused};

// The writers of a guarded server filter for readers of the library's classes: every filter change
// is locked here. Unguarded (an unknown Fast DDS), the classes stay unknown to the server, which
// then sends such readers everything, as to plain ones.
CFT_EXPORT void *cft_find(void *self, const char *class_name) __asm__(FIND);
void *cft_find(void *self, const char *class_name) {
  int fam = cft_loaded_family();
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
    cft_family_missing(f, FN_FIND);
    return NULL;
  }
  void *theirs = real(self, class_name);
  if (active && theirs == NULL) cft_filter_class_unknown(class_name);
  return theirs;
}


// 0: lookups of the library's filter classes answered; 1: filters of those classes created (for
// the writers and readers of this process); 2: their verdicts; 3: filters created or changed.
CFT_EXPORT unsigned long cft_guard_filter_class_count(int which) {
  if (which == 2) return cft_filter_class_total_verdicts();
  if (which == 3) return cft_filter_class_total_changes();
  return __atomic_load_n(which == 0 ? &filter_class_lookups : &filter_class_filters,
                         __ATOMIC_RELAXED);
}


// How often each interposed member was called: 0 perform_create_new_change,
// 1 process_reader_filter_info, 2 remove_reader_filter, 3 nested writes that went on unlocked.
CFT_EXPORT unsigned long cft_guard_call_count(int which) {
  if (which >= 0 && which < FN_LOCKED) return __atomic_load_n(&call_counts[which], __ATOMIC_RELAXED);
  if (which == FN_LOCKED) return __atomic_load_n(&degraded_count, __ATOMIC_RELAXED);
  return 0;
}
