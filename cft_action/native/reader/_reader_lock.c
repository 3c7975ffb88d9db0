// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The reader-side twin of the server guard, for the process that changes its filters.
//
// A Fast DDS DataReader (2.14 and 3.x alike) evaluates its filter itself, in a receive thread, for
// every sample whose writer did not filter for the reader's current filter: right after each filter
// change, until the writer has the change. ContentFilteredTopicImpl::set_expression_parameters
// meanwhile has DDSFilterFactory::create_content_filter build a new expression and clear the old
// one, with no lock against that evaluation: the receive thread then evaluates a cleared expression
// and the process dies (SIGSEGV in TypeDescriptor::get_element_type under
// DDSFilterExpression::evaluate, under ContentFilteredTopicImpl::is_relevant). Measured: a
// subscription that changed its filter in a loop while a publisher in another process sent at full
// rate died within seconds.
//
// This library, loaded with ctypes into the client's process (not preloaded), replaces two slots of
// libfastrtps's vtables at run time: ContentFilteredTopicImpl::is_relevant (both its entry and the
// thunk through IReaderDataFilter) takes a read lock, and DDSFilterFactory::create_content_filter,
// where the reader's expression is swapped, takes the write lock. The slots are found by their
// current value, the exported address of the member, so no object layout is assumed. Readers that
// hold their RTPSReader's mutex wait only for the swap itself, which takes no reader mutex, so the
// lock order cannot cycle. Fast DDS 3.2 (Kilted's wheels) and 3.6 (Lyrical) have the same members
// and vtables under their own sonames and 3.x's mangling (GUID_t and CacheChange_t moved to
// eprosima::fastdds::rtps; create_content_filter's name did not change): one row of `families`
// each, the first whose library is loaded is patched.
#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "_patch.h"

#define EXPORT __attribute__((visibility("default")))

#define CFT_VTABLE "_ZTVN8eprosima7fastdds3dds24ContentFilteredTopicImplE"
#define IS_RELEVANT_OF(args) "_ZNK8eprosima7fastdds3dds24ContentFilteredTopicImpl" args
#define IS_RELEVANT_THUNK_OF(args) "_ZThn16_NK8eprosima7fastdds3dds24ContentFilteredTopicImpl" args
#define IS_RELEVANT_ARGS2 "11is_relevantERKNS_8fastrtps4rtps13CacheChange_tERKNS4_6GUID_tE"
#define IS_RELEVANT_ARGS3 "11is_relevantERKNS0_4rtps13CacheChange_tERKNS3_6GUID_tE"
// A family's three names, by the mangling of is_relevant's arguments.
#define NAMES_OF(args) {IS_RELEVANT_OF(args), IS_RELEVANT_THUNK_OF(args), CREATE_FILTER}
#define FACTORY_VTABLE "_ZTVN8eprosima7fastdds3dds12DDSSQLFilter16DDSFilterFactoryE"
#define CREATE_FILTER                                                                          \
  "_ZN8eprosima7fastdds3dds12DDSSQLFilter16DDSFilterFactory21create_content_filterEPKcS5_PKN" \
  "S1_13TopicDataTypeES5_RKNS1_23LoanableTypedCollectionIS5_St17integral_constantIbLb1EEEERP" \
  "NS1_14IContentFilterE"

typedef bool (*is_relevant_fn)(const void *self, const void *change, const void *reader_guid);
// ReturnCode_t is a trivially copyable class of one uint32_t: returned in a register.
typedef uint32_t (*create_fn)(void *self, const char *filter_class, const char *type_name,
                              const void *data_type, const char *expression,
                              const void *parameters, void **filter_instance);

static pthread_rwlock_t filters_lock = PTHREAD_RWLOCK_INITIALIZER;
static __thread int holds_write_lock;  // create_content_filter may re-enter on this thread
static is_relevant_fn real_is_relevant, real_is_relevant_thunk;
static create_fn real_create;
static unsigned long evaluations, replacements;  // under the lock; read relaxed
static struct cft_install installed = CFT_INSTALL_INIT;

static bool read_locked(is_relevant_fn real, const void *self, const void *change,
                        const void *guid) {
  if (holds_write_lock) return real(self, change, guid);
  pthread_rwlock_rdlock(&filters_lock);
  __atomic_fetch_add(&evaluations, 1, __ATOMIC_RELAXED);
  bool relevant = real(self, change, guid);
  pthread_rwlock_unlock(&filters_lock);
  return relevant;
}

static bool locked_is_relevant(const void *self, const void *change, const void *guid) {
  return read_locked(real_is_relevant, self, change, guid);
}

static bool locked_is_relevant_thunk(const void *self, const void *change, const void *guid) {
  return read_locked(real_is_relevant_thunk, self, change, guid);
}

static uint32_t locked_create(void *self, const char *filter_class, const char *type_name,
                              const void *data_type, const char *expression,
                              const void *parameters, void **filter_instance) {
  if (holds_write_lock)
    return real_create(self, filter_class, type_name, data_type, expression, parameters,
                       filter_instance);
  pthread_rwlock_wrlock(&filters_lock);
  holds_write_lock = 1;
  __atomic_fetch_add(&replacements, 1, __ATOMIC_RELAXED);
  uint32_t ret = real_create(self, filter_class, type_name, data_type, expression, parameters,
                             filter_instance);
  holds_write_lock = 0;
  pthread_rwlock_unlock(&filters_lock);
  return ret;
}

// The Fast DDS builds whose members were checked: soname, is_relevant, its thunk, the factory's
// create_content_filter.
static const struct family {
  const char *soname;
  const char *names[3];
} families[] = {
  {"libfastrtps.so.2.14", NAMES_OF(IS_RELEVANT_ARGS2)},
  {"libfastdds.so.3.6", NAMES_OF(IS_RELEVANT_ARGS3)},
  {"libfastdds.so.3.2", NAMES_OF(IS_RELEVANT_ARGS3)},
};
#define N_FAMILIES (sizeof families / sizeof families[0])

static int install(struct cft_install *once) {
  const struct family *family = NULL;
  char known[128] = "";
  for (size_t i = 0, used = 0; i < N_FAMILIES && family == NULL; i++) {
    void *loaded = dlopen(families[i].soname, RTLD_NOW | RTLD_NOLOAD);
    if (loaded != NULL) {
      dlclose(loaded);
      family = &families[i];
    } else if (used < sizeof known) {
      used += snprintf(known + used, sizeof known - used, "%s%s", i ? ", " : "",
                       families[i].soname);
    }
  }
  if (family == NULL)
    return cft_install_fail(once, -1, "no Fast DDS whose members it knows is loaded", known);
  void *resolved[3];
  int status;
  void *library = cft_resolve(once, family->soname, family->names, 3, resolved, &status);
  if (library == NULL) return status;
  real_is_relevant = (is_relevant_fn)resolved[0];
  real_is_relevant_thunk = (is_relevant_fn)resolved[1];
  real_create = (create_fn)resolved[2];
  int creates = cft_patch_vtable(library, FACTORY_VTABLE, (void *)real_create, (void *)locked_create);
  if (creates < 1)
    return cft_install_fail(once, -3, "no create_content_filter slot in", FACTORY_VTABLE);
  int entries = cft_patch_vtable(library, CFT_VTABLE, (void *)real_is_relevant,
                             (void *)locked_is_relevant);
  int thunks = cft_patch_vtable(library, CFT_VTABLE, (void *)real_is_relevant_thunk,
                            (void *)locked_is_relevant_thunk);
  if (thunks < 1 || entries < 0)
    return cft_install_fail(once, -4, "no is_relevant slot in", CFT_VTABLE);
  return 0;
}

// 0 once installed (later calls return at once), < 0 if it cannot be: see cft_reader_lock_error.
EXPORT int cft_reader_lock_install(void) { return cft_install_once(&installed, install); }

EXPORT const char *cft_reader_lock_error(void) { return installed.error; }

// 0: filter evaluations by readers that took the read lock; 1: filter replacements.
EXPORT unsigned long cft_reader_lock_count(int which) {
  return __atomic_load_n(which == 0 ? &evaluations : &replacements, __ATOMIC_RELAXED);
}
