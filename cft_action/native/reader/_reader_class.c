// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The library's filter classes (_filter_class.h) in a client's process, where cft_action is
// loaded with ctypes after Fast DDS, so nothing can be preloaded. Two PLT slots of libfastrtps are
// redirected:
// - DomainParticipantImpl::find_content_filter_factory answers the classes with this library's
//   factories (unless the slot is already redirected: the guard is preloaded and answers them);
// - DomainParticipantImpl::create_contentfilteredtopic, which rmw_fastrtps reaches through
//   DomainParticipant's four-argument overload with the class DDSSQL, takes the class named by
//   cft_filter_class_begin instead, on the thread inside cft_filter_class_begin/end.
// The factory creates filters only on such a thread: those are the process's own readers. A writer
// of this process that discovers a reader with this class gets no filter for it (the factory says
// unsupported), so it sends that reader everything and filters nothing, unguarded.
// Besides the shared classes it answers one of its own, CFT_STATUS_CLASS (_status_trim.h), which
// the guard answers its own way, for its status writers (native/guard/_guard_status.c;
// docs/INTERNALS.md section 20).
#include <string.h>

#include "_patch.h"
#include "_fastdds_layout.h"
#include "_filter_class.h"
#include "_status_trim.h"

#define EXPORT __attribute__((visibility("default")))

#define FASTRTPS_SONAME "libfastrtps.so.2.14"
#define FIND "_ZN8eprosima7fastdds3dds21DomainParticipantImpl27find_content_filter_factoryEPKc"
#define CREATE_CFT                                                                               \
  "_ZN8eprosima7fastdds3dds21DomainParticipantImpl27create_contentfilteredtopicERKNSt7__cxx1112" \
  "basic_stringIcSt11char_traitsIcESaIcEEEPNS1_5TopicESA_RKSt6vectorIS8_SaIS8_EEPKc"

typedef void *(*find_fn)(void *self, const char *class_name);
typedef void *(*create_cft_fn)(void *self, const void *name, void *related_topic,
                               const void *expression, const void *parameters,
                               const char *class_name);

static find_fn real_find;
static create_cft_fn real_create_cft;
static __thread const char *requested;  // the class, inside cft_filter_class_begin/end
static __thread void *created;           // the filter a factory created last on this thread
static struct cft_install installed = CFT_INSTALL_INIT;  // 0: ours; 2: the guard answers

static bool may_create(void) { return requested != NULL; }
static void remember(void *filter) { created = filter; }
static const struct cft_filter_class_owner reader_owner = {may_create, remember, CFT_STATUS_CLASS,
                                                          &cft_status_grammar};

static void *find(void *self, const char *class_name) {
  void *factory = cft_filter_factory_for(class_name, &reader_owner);
  return factory != NULL ? factory : real_find(self, class_name);
}

static void *create_cft(void *self, const void *name, void *related_topic, const void *expression,
                        const void *parameters, const char *class_name) {
  return real_create_cft(self, name, related_topic, expression, parameters,
                         requested != NULL ? requested : class_name);
}

static int install(struct cft_install *once) {
  // The classes judge samples by the layout of the Fast DDS 2.14 headers (Fast DDS 3: none).
  if (!CFT_LAYOUT_KNOWN)
    return cft_install_fail(once, -5, "this build has no Fast DDS 2.14 layout", CFT_LAYOUT_SOURCE);
  static const char *const names[] = {FIND, CREATE_CFT};
  void *resolved[2];
  int status;
  if (cft_resolve(once, FASTRTPS_SONAME, names, 2, resolved, &status) == NULL) return status;
  real_find = (find_fn)resolved[0];
  real_create_cft = (create_cft_fn)resolved[1];
  int ours = cft_patch_got(FASTRTPS_SONAME, FIND, (void *)real_find, (void *)find);
  if (ours < 0) return cft_install_fail(once, -3, "no PLT slot in " FASTRTPS_SONAME " for", FIND);
  if (cft_patch_got(FASTRTPS_SONAME, CREATE_CFT, (void *)real_create_cft, (void *)create_cft) != 1)
    return cft_install_fail(once, -4, "no PLT slot in " FASTRTPS_SONAME " for", CREATE_CFT);
  return ours == 1 ? 0 : 2;
}

// 0 once this library answers the class, 2 if the preloaded guard does, < 0 if neither can be
// arranged (cft_filter_class_error says why). Later calls return the first result.
EXPORT int cft_filter_class_install(void) { return cft_install_once(&installed, install); }

EXPORT const char *cft_filter_class_error(void) { return installed.error; }

// Around one rcl content-filter call for a reader that is to use `class_name` (CFT_UUID_CLASS,
// CFT_NODE_CLASS or CFT_STATUS_CLASS; another name makes the call a plain DDS-SQL one).
EXPORT void cft_filter_class_begin(const char *class_name) {
  // The caller's string may not outlive this call.
  requested = class_name != NULL && strcmp(class_name, CFT_STATUS_CLASS) == 0
                  ? CFT_STATUS_CLASS
                  : cft_filter_class_name(class_name);
  created = NULL;
}

// Ends the request; returns the filter this library created in it (new readers only), or NULL.
EXPORT void *cft_filter_class_end(void) {
  requested = NULL;
  void *filter = created;
  created = NULL;
  return filter;
}

// Whether one of the shared classes compiles `expression` in this build: asked before a first
// filter, since a first filter that rmw_fastrtps cannot create leaves its reader dangling.
EXPORT bool cft_filter_class_accepts(const char *class_name, const char *expression) {
  return cft_filter_class_compiles(class_name, expression);
}

EXPORT unsigned long cft_filter_class_rate_mismatches(void) { return cft_rate_layout_mismatches(); }

EXPORT unsigned long cft_filter_class_verdicts(const void *filter) {
  return filter != NULL ? cft_filter_verdicts(filter) : 0;
}
