// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's third part: how many readers a writer filters for.
//
// A Fast DDS 2.14 DataWriter keeps writer-side filters for at most
// writer_resource_limits().reader_filters_allocation.maximum readers, 32 by default, and XML
// cannot set it. A filtered reader beyond that is matched without its filter: it receives every
// sample, each with the filter signatures of the 32, and filters it itself (ReaderFilterCollection::
// process_reader_filter_info returns when the collection is full, and does not look again when a
// reader leaves). Past 32 filtered clients per action, those clients receive more bytes than plain
// ones (docs/BENCHMARKS.md, "The knee past 32 filtered readers").
//
// rmw_fastrtps_cpp fills every DataWriterQos with get_datawriter_qos() of
// librmw_fastrtps_shared_cpp, through the PLT, just before Publisher::create_datawriter: the last
// word on the QoS of every writer it makes. The definition below calls the real one, then raises
// that maximum to CFT_ACTION_READER_FILTERS (default 1024) in the QoS it filled. It does so only
// where the guard locks (the Fast DDS 2.14 it knows, loaded after the guard), and only where the
// three size_t at the known offset read as Fast DDS's default {0, 32, 1}; otherwise it leaves the
// QoS alone and says why, once.
//
// The maximum is only a bound: the filter collection and every change's list of filtered-out
// readers grow as readers come. What grows with it is PID_CONTENT_FILTER_INFO, 16 bytes per
// filtered reader in every DATA, whose 16-bit length caps it at 4063 readers (readers of the
// library's classes are not in it: _guard_filter.c keeps them).
//
// The same call marks the writer in its discovery data. get_datawriter_qos fills USER_DATA with
// what rmw_dds_common::encode_type_hash_for_user_data_qos (librmw_dds_common, through the PLT)
// returns, "typehash=...;". Inside the guard's get_datawriter_qos, where the guard filters for the
// library's classes, the definition below appends CFT_WRITER_MARK to it: since the samples of such
// a writer carry no filter signature for those classes, that is how a reader's process tells a
// writer that filters for it from one that does not (_writer_marks.c). Readers are not marked.

#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <limits.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "_fastdds_layout.h"
#include "_filter_class.h"
#include "_guard_families.h"
#include "_guard_log.h"

#define GET_DATAWRITER_QOS \
  "_Z18get_datawriter_qosRK17rmw_qos_profile_sRK18rosidl_type_hash_sRN8eprosima7fastdds3dds13DataWriterQosE"
#define RMW_SHARED_SONAME "librmw_fastrtps_shared_cpp.so"
#define ENCODE_TYPE_HASH                                                                         \
  "_ZN14rmw_dds_common34encode_type_hash_for_user_data_qosERK18rosidl_type_hash_sRNSt7__cxx1112" \
  "basic_stringIcSt11char_traitsIcESaIcEEE"
#define RMW_DDS_COMMON_SONAME "librmw_dds_common.so"
// std::string::append(const char *) of libstdc++'s C++11 ABI, the std::string rmw passes.
#define STRING_APPEND "_ZNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEE6appendEPKc"
#define LIBSTDCXX_SONAME "libstdc++.so.6"

// The offset of writer_resource_limits().reader_filters_allocation in DataWriterQos, a
// ResourceLimitedContainerConfig {size_t initial, maximum, increment}, from the headers the guard
// was built against (_fastdds_layout.h: DWQ_READER_FILTERS). The same on the wheels' 2.14.5, apt's
// 2.14.6 (SECURITY=ON) and the 2.14.x head (docs/COMPATIBILITY.md): security adds no QoS member.
// At run time it is used only where it holds Fast DDS's default {0, 32, 1}, which
// rmw_fastrtps's get_datawriter_qos never changes: anything else there means another layout.
static const size_t fastdds_default[3] = {0, 32, 1};

#define DEFAULT_READER_FILTERS 1024
#define MAX_READER_FILTERS 4063  // 12 + 4 * ceil(n / 32) + 16 * n must fit in 16 bits

typedef bool (*get_datawriter_qos_fn)(const void *profile, const void *type_hash, void *qos);

enum { RAISED = 0, LEFT = 1, COUNTERS = 2 };
static unsigned long counters[COUNTERS];
static void *real_get_datawriter_qos;  // cft_guard_real's cache
static size_t wanted;  // 0 until read from the environment
static char left_reason[256];

static void say_left_once(void) {
  static int told;
  if (!__atomic_exchange_n(&told, 1, __ATOMIC_RELAXED))
    cft_say("writers keep Fast DDS's limit of 32 filtered readers: %s", left_reason);
}

// CFT_ACTION_READER_FILTERS, or the default; an unusable value keeps Fast DDS's 32, and says so.
static size_t reader_filters_wanted(void) {
  size_t n = __atomic_load_n(&wanted, __ATOMIC_RELAXED);
  if (n != 0) return n;
  const char *text = getenv("CFT_ACTION_READER_FILTERS");
  n = DEFAULT_READER_FILTERS;
  if (text != NULL && text[0] != '\0') {
    char *end;
    errno = 0;
    unsigned long v = strtoul(text, &end, 10);
    if (errno != 0 || *end != '\0' || text[0] == '-' || v < 1 || v > MAX_READER_FILTERS) {
      snprintf(left_reason, sizeof left_reason,
               "CFT_ACTION_READER_FILTERS=%.40s is not a number from 1 to %d", text,
               MAX_READER_FILTERS);
      n = fastdds_default[1];
      say_left_once();
    } else {
      n = v;
    }
  }
  __atomic_store_n(&wanted, n, __ATOMIC_RELAXED);
  return n;
}

static get_datawriter_qos_fn find_real(void) {
  return (get_datawriter_qos_fn)cft_guard_real(&real_get_datawriter_qos,
                                               RMW_SHARED_SONAME, GET_DATAWRITER_QOS);
}

static void raise_reader_filters(void *qos) {
  size_t n = reader_filters_wanted();
  if (n == fastdds_default[1]) return;
  if (!cft_guard_knows_fastdds2()) {
    snprintf(left_reason, sizeof left_reason,
             "the guard knows the DataWriterQos layout of Fast DDS 2.14 only");
    __atomic_fetch_add(&counters[LEFT], 1, __ATOMIC_RELAXED);
    say_left_once();
    return;
  }
#if CFT_LAYOUT_KNOWN
  size_t *config = (size_t *)((char *)qos + DWQ_READER_FILTERS);
  if (config[0] != fastdds_default[0] || config[1] != fastdds_default[1] ||
      config[2] != fastdds_default[2]) {
    snprintf(left_reason, sizeof left_reason,
             "the DataWriterQos does not hold {0, 32, 1} where %.200s keep "
             "reader_filters_allocation (it holds {%zu, %zu, %zu})", CFT_LAYOUT_SOURCE, config[0],
             config[1], config[2]);
    __atomic_fetch_add(&counters[LEFT], 1, __ATOMIC_RELAXED);
    say_left_once();
    return;
  }
  config[1] = n;
  __atomic_fetch_add(&counters[RAISED], 1, __ATOMIC_RELAXED);
#else
  (void)qos;
  snprintf(left_reason, sizeof left_reason, "the guard knows no DataWriterQos layout: it was built "
           "from %s", CFT_LAYOUT_SOURCE);
  __atomic_fetch_add(&counters[LEFT], 1, __ATOMIC_RELAXED);
  say_left_once();
#endif
}

// ---- the writer's mark --------------------------------------------------------------------------
typedef int32_t (*encode_fn)(const void *type_hash, void *string_out);  // rmw_ret_t, std::string &
typedef void *(*append_fn)(void *string, const char *text);
static __thread bool marking;  // inside the guard's get_datawriter_qos of a writer it filters for
static unsigned long marked;
static encode_fn real_encode;
static append_fn string_append;

static void find_encode(void) {
  if (__atomic_load_n(&real_encode, __ATOMIC_ACQUIRE) != NULL) return;
  // The handles are kept on purpose: the pointers must not outlive the libraries.
  void *common = dlopen(RMW_DDS_COMMON_SONAME, RTLD_LAZY | RTLD_NOLOAD);
  void *cxx = dlopen(LIBSTDCXX_SONAME, RTLD_LAZY | RTLD_NOLOAD);
  void *append = cxx != NULL ? dlsym(cxx, STRING_APPEND) : NULL;
  void *encode = common != NULL ? dlsym(common, ENCODE_TYPE_HASH) : NULL;
  if (encode == NULL) encode = dlsym(RTLD_NEXT, ENCODE_TYPE_HASH);
  __atomic_store_n(&string_append, (append_fn)append, __ATOMIC_RELAXED);
  __atomic_store_n(&real_encode, (encode_fn)encode, __ATOMIC_RELEASE);
}

CFT_EXPORT int32_t cft_encode_type_hash(const void *type_hash, void *string_out)
    __asm__(ENCODE_TYPE_HASH);
int32_t cft_encode_type_hash(const void *type_hash, void *string_out) {
  find_encode();
  encode_fn real = __atomic_load_n(&real_encode, __ATOMIC_ACQUIRE);
  if (real == NULL) {
    // Only rmw calls this, and it is linked against the real one: not reached in practice. rmw
    // then goes on without the type hash in USER_DATA, and says so.
    cft_say("no real definition of encode_type_hash_for_user_data_qos");
    return 1;  // RMW_RET_ERROR
  }
  int32_t ret = real(type_hash, string_out);
  append_fn append = __atomic_load_n(&string_append, __ATOMIC_RELAXED);
  if (ret == 0 && marking && append != NULL) {
    append(string_out, CFT_WRITER_MARK);
    __atomic_fetch_add(&marked, 1, __ATOMIC_RELAXED);
  }
  return ret;
}

CFT_EXPORT bool cft_get_datawriter_qos(const void *profile, const void *type_hash, void *qos)
    __asm__(GET_DATAWRITER_QOS);
bool cft_get_datawriter_qos(const void *profile, const void *type_hash, void *qos) {
  get_datawriter_qos_fn real = find_real();
  if (real == NULL) {
    // Only rmw_fastrtps calls this, and it is linked against the real one: not reached in
    // practice. Failing makes rmw fail the writer's creation with an error, not crash.
    cft_say("no real definition of get_datawriter_qos; the writer is not created");
    return false;
  }
  // The guard filters for the library's classes where it locks (cft_find2 in _guard.c).
  marking = cft_guard_knows_fastdds2();
  bool ok = real(profile, type_hash, qos);
  marking = false;
  if (ok) raise_reader_filters(qos);
  return ok;
}

// ---- the C API, for ctypes -----------------------------------------------------------------------
// 0: writers whose limit was raised; 1: writers left at Fast DDS's 32 (see the stderr line);
// 2: the maximum that raised writers get; 3: writers marked in their discovery data.
CFT_EXPORT unsigned long cft_guard_writer_qos_count(int which) {
  if (which >= 0 && which < COUNTERS) return __atomic_load_n(&counters[which], __ATOMIC_RELAXED);
  if (which == COUNTERS) return reader_filters_wanted();
  if (which == COUNTERS + 1) return __atomic_load_n(&marked, __ATOMIC_RELAXED);
  return 0;
}

// The layout this file assumes, for the header probe: 0: DWQ_READER_FILTERS; -1 past the end, and
// in a build without headers.
CFT_EXPORT long cft_guard_writer_qos_layout(int which) {
#if CFT_LAYOUT_KNOWN
  return which == 0 ? DWQ_READER_FILTERS : -1;
#else
  (void)which;
  return -1;
#endif
}
