// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's view of the endpoints rcl creates: the part that hands an action's writers to
// the loaded Fast DDS family's layer, through public API only.
//
// rcl_action_server_init creates an action's three services with rcl_service_init, a call from
// librcl_action into librcl through the PLT, which a preloaded definition therefore interposes
// (rclpy's and rclcpp's servers, and any rcl_action server in C, make it so). This file defines
// rcl_service_init: it calls rcl's own, then, for a service whose name is one of an action's
// (_guard_replies.c decides), hands it to the layer of the loaded family:
// - Fast DDS 3.3+: the service's response writer (rmw_fastrtps_cpp's public
//   get_response_datawriter on rcl_service_get_rmw_handle's rmw handle) gets a sample prefilter
//   from fastdds3/_prefilter.cpp, which asks _guard_replies.c's cft_reply_verdict for each reply
//   and reader. That layer is a library of its own (_cftguard_fastdds3, next to this one), built
//   against Fast DDS 3.3+ headers and linked against that Fast DDS; it is dlopened only where its
//   soname (CFT_FASTDDS3_SONAME) is already loaded and the guard locks it (a Fast DDS 3 it knows);
// - Fast DDS 2.14 marks its reply writers itself, from the readers they match (_guard_replies.c),
//   and nothing is done here.
// Where the layer cannot be used (not built, another Fast DDS, another rmw), every reply goes to
// every client as rmw_fastrtps sends it, and the first endpoint that would use it says once why
// (cft_guard_prefilter_state too). rcl's definitions are found in the loaded librcl (ROS loads it
// in a local scope: RTLD_NEXT does not see it). CFT_GUARD_REPLIES=off (or 0) leaves every service
// as rcl made it.
// It defines rcl_publisher_init, rcl_publish and rcl_publisher_fini too: on Fast DDS 3.3+ an
// action's feedback and status writers get routings to the readers that mark themselves
// (_guard_feedback.c, _guard_status.c), every other writer one to readers that mark a program
// (_guard_programs.c); rcl_publish brings a routing's knowledge of the marks up to date before each
// write, and rcl_publisher_fini gives the routing back.

#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "_fastdds_layout.h"
#include "_filter_class.h"
#include "_guard_families.h"
#include "_guard_feedback.h"
#include "_guard_log.h"
#include "_guard_programs.h"
#include "_guard_replies.h"
#include "_guard_status.h"
#include "fastdds3/_prefilter.h"
#include "fastdds3/_rtps_types.h"

// setup.py's _fastdds_layout.h says whether the layer was built; a layout header written otherwise
// (the tests' made-up layouts) does not, and has none.
#ifndef CFT_FASTDDS3_PREFILTER
#define CFT_FASTDDS3_PREFILTER 0
#define CFT_FASTDDS3_SONAME ""
#define CFT_FASTDDS3_SOURCE "a _fastdds_layout.h that setup.py did not write"
#endif

#define SERVICE_INIT "rcl_service_init"
#define SERVICE_RMW_HANDLE "rcl_service_get_rmw_handle"
#define SERVICE_NAME "rcl_service_get_service_name"
#define PUBLISHER_INIT "rcl_publisher_init"
#define PUBLISH "rcl_publish"
#define PUBLISHER_FINI "rcl_publisher_fini"
#define PUBLISHER_RMW_HANDLE "rcl_publisher_get_rmw_handle"
#define PUBLISHER_TOPIC "rcl_publisher_get_topic_name"
#define RESPONSE_WRITER "_ZN16rmw_fastrtps_cpp23get_response_datawriterEP13rmw_service_s"
#define DATAWRITER "_ZN16rmw_fastrtps_cpp14get_datawriterEP15rmw_publisher_s"
// This library's file name starts with GUARD_NAME; the layer's, in the same folder, with
// LAYER_NAME, the rest being the same (the Python extension suffix).
#define GUARD_NAME "_cftguard"
#define LAYER_NAME "_cftguard_fastdds3"

// rcl_service_init's and rcl_publisher_init's: (endpoint, node, type support, name, options).
typedef int32_t (*init_fn)(void *endpoint, const void *node, const void *type_support,
                           const char *name, const void *options);
typedef void *(*handle_fn)(const void *object);
typedef const char *(*name_fn)(const void *object);
typedef int32_t (*publish_fn)(const void *publisher, const void *message, void *allocation);
typedef int32_t (*fini_fn)(void *endpoint, void *node);

static struct {
  init_fn init;
  handle_fn rmw_handle;
  name_fn name;
  init_fn publisher_init;
  publish_fn publish;
  fini_fn publisher_fini;
  handle_fn publisher_rmw_handle;
  name_fn topic;
} rcl;
static pthread_once_t rcl_once = PTHREAD_ONCE_INIT;
static void resolve_rcl(void);

// Says that rcl has no definition of `name` after the guard's: rcl's error code.
static int32_t missing(const char *name) {
  cft_say("no %s after the guard's: it cannot be done", name);
  return 1;  // RCL_RET_ERROR
}

static void resolve_rcl(void) {
  rcl.init = (init_fn)cft_guard_loaded_symbol(SERVICE_INIT, "librcl");
  rcl.rmw_handle = (handle_fn)cft_guard_loaded_symbol(SERVICE_RMW_HANDLE, "librcl");
  rcl.name = (name_fn)cft_guard_loaded_symbol(SERVICE_NAME, "librcl");
  rcl.publisher_init = (init_fn)cft_guard_loaded_symbol(PUBLISHER_INIT, "librcl");
  rcl.publish = (publish_fn)cft_guard_loaded_symbol(PUBLISH, "librcl");
  rcl.publisher_fini = (fini_fn)cft_guard_loaded_symbol(PUBLISHER_FINI, "librcl");
  rcl.publisher_rmw_handle = (handle_fn)cft_guard_loaded_symbol(PUBLISHER_RMW_HANDLE, "librcl");
  rcl.topic = (name_fn)cft_guard_loaded_symbol(PUBLISHER_TOPIC, "librcl");
}

// ---- the Fast DDS 3 layer -----------------------------------------------------------------------
// Written once by load_layer (then published with release), read from any thread.
static char layer_text[640];
static const char *layer_state = "off: no action endpoint created yet";
static struct {
  cft_fastdds3_route_replies_fn route_replies;
  cft_fastdds3_route_marked_fn route_marked;
  cft_fastdds3_marked_readers_fn marked_readers;
  cft_fastdds3_release_fn release;
  handle_fn response_writer;
  handle_fn datawriter;
} layer;
static pthread_once_t layer_once = PTHREAD_ONCE_INIT;

// The layer's path: this library's, with LAYER_NAME for GUARD_NAME; false if it is not one.
static bool layer_path(char *path, size_t size) {
  Dl_info self;
  if (dladdr((void *)layer_path, &self) == 0 || self.dli_fname == NULL) return false;
  const char *base = strrchr(self.dli_fname, '/');
  base = base != NULL ? base + 1 : self.dli_fname;
  if (strncmp(base, GUARD_NAME, strlen(GUARD_NAME)) != 0) return false;
  int n = snprintf(path, size, "%.*s%s%s", (int)(base - self.dli_fname), self.dli_fname,
                   LAYER_NAME, base + strlen(GUARD_NAME));
  return n > 0 && (size_t)n < size;
}

// Decided once, at the first action service of a process of Fast DDS 3: whether the layer is
// used, else why not (said once).
static void load_layer(void) {
  char why[512] = "";
  struct family *f = cft_family_ready(1);
  char path[4096];
  cft_fastdds3_rtps_types_fn rtps_types = NULL;
  if (!CFT_FASTDDS3_PREFILTER) {
    snprintf(why, sizeof why, "not built (%s)", CFT_FASTDDS3_SOURCE);
  } else if (__atomic_load_n(&f->state, __ATOMIC_ACQUIRE) != CFT_GUARD_ACTIVE) {
    snprintf(why, sizeof why, "the guard does not lock this Fast DDS 3 (%.400s)", f->reason);
  } else if (dlopen(CFT_FASTDDS3_SONAME, RTLD_LAZY | RTLD_NOLOAD) == NULL) {
    snprintf(why, sizeof why, "the loaded Fast DDS is not %s, the one the layer was built with",
             CFT_FASTDDS3_SONAME);
  } else if ((layer.response_writer = (handle_fn)cft_guard_loaded_symbol(
                  RESPONSE_WRITER, "rmw_fastrtps_cpp")) == NULL ||
             (layer.datawriter = (handle_fn)cft_guard_loaded_symbol(
                  DATAWRITER, "rmw_fastrtps_cpp")) == NULL) {
    snprintf(why, sizeof why, "no rmw_fastrtps_cpp::get_response_datawriter or get_datawriter is "
             "loaded (another rmw implementation)");
  } else if (!layer_path(path, sizeof path)) {
    snprintf(why, sizeof why, "the guard library's file name does not start with %s", GUARD_NAME);
  } else {
    // Kept open for the process's life: the prefilters' code is in it.
    void *handle = dlopen(path, RTLD_LAZY | RTLD_LOCAL);
    if (handle != NULL) {
      layer.route_replies =
          (cft_fastdds3_route_replies_fn)dlsym(handle, CFT_FASTDDS3_ROUTE_REPLIES);
      layer.route_marked = (cft_fastdds3_route_marked_fn)dlsym(handle, CFT_FASTDDS3_ROUTE_MARKED);
      layer.marked_readers =
          (cft_fastdds3_marked_readers_fn)dlsym(handle, CFT_FASTDDS3_MARKED_READERS);
      layer.release = (cft_fastdds3_release_fn)dlsym(handle, CFT_FASTDDS3_RELEASE);
      rtps_types = (cft_fastdds3_rtps_types_fn)dlsym(handle, CFT_FASTDDS3_RTPS_TYPES);
    }
    if (layer.route_replies == NULL || layer.route_marked == NULL ||
        layer.marked_readers == NULL || layer.release == NULL || rtps_types == NULL) {
      snprintf(why, sizeof why, "cannot load %.250s: %.150s", path, dlerror());
      layer.route_replies = NULL, layer.route_marked = NULL;
    }
  }
  if (why[0] != '\0') {
    snprintf(layer_text, sizeof layer_text, "off: %s", why);
    cft_say("the Fast DDS 3 layer is off: %s; replies, feedback and status go to every client",
            why);
  } else {
    snprintf(layer_text, sizeof layer_text, "on: %.250s, built with %.300s", path,
             CFT_FASTDDS3_SOURCE);
    cft_fastdds3_types_loaded(rtps_types());
  }
  __atomic_store_n(&layer_state, layer_text, __ATOMIC_RELEASE);
}

// Whether an endpoint that rcl made (`is_action`: one of an action's that the guard routes) gets
// the layer: in a process of Fast DDS 3, where the layer loads (at the first such endpoint).
static bool layer_for(bool is_action) {
  if (!is_action || cft_loaded_family() != 1) return false;
  pthread_once(&layer_once, load_layer);
  return layer.route_replies != NULL;
}

// A service that rcl made: an action's, in a process of Fast DDS 3, gets its replies routed.
static void service_created(const void *service) {
  if (!cft_replies_wanted() || rcl.name == NULL || rcl.rmw_handle == NULL) return;
  const char *name = rcl.name(service);
  if (!layer_for(cft_replies_is_action_service(name))) return;
  void *writer = layer.response_writer(rcl.rmw_handle(service));
  int32_t ret = writer != NULL ? layer.route_replies(writer, cft_reply_verdict) : -1;
  if (ret == 0)
    cft_replies_writer_routed(name);
  else
    cft_say("the replies of %.200s go to every client: %s (%d)", name,
            writer == NULL ? "it has no rmw_fastrtps_cpp response writer"
                           : "DataWriter::set_sample_prefilter refused", (int)ret);
}

CFT_EXPORT int32_t rcl_service_init(void *service, const void *node, const void *type_support,
                                    const char *service_name, const void *options);
// rcl's rcl_service_init (`service`) or rcl_publisher_init, then service_created or
// publisher_created for the endpoint when it was made.
static void publisher_created(const void *publisher);
static int32_t init_endpoint(bool service, void *endpoint, const void *node,
                             const void *type_support, const char *name, const void *options) {
  pthread_once(&rcl_once, resolve_rcl);
  init_fn real = service ? rcl.init : rcl.publisher_init;
  if (real == NULL) return missing(service ? SERVICE_INIT : PUBLISHER_INIT);
  int32_t ret = real(endpoint, node, type_support, name, options);
  if (ret == 0) (service ? service_created : publisher_created)(endpoint);
  return ret;
}

int32_t rcl_service_init(void *service, const void *node, const void *type_support,
                         const char *service_name, const void *options) {
  return init_endpoint(true, service, node, type_support, service_name, options);
}

// ---- routed publishers --------------------------------------------------------------------------
// The routed publishers (rcl_publisher_t *, never read) with the layer's handle, in a table
// addressed by the publisher's address (linear probing): every publisher of a guarded process is
// routed (the programs' kind takes any topic), and rcl_publish looks its own up at each write.
// Past ROUTED_MAX - 1, a writer stays as rmw made it, said.
#define ROUTED_MAX 1024
static struct {
  const void *publisher;  // NULL: a free slot
  void *routing;
} routed[ROUTED_MAX];
static int routed_count;
static pthread_mutex_t routed_lock = PTHREAD_MUTEX_INITIALIZER;

static size_t slot_of(const void *publisher) {
  uintptr_t a = (uintptr_t)publisher;
  return (size_t)((a >> 4) ^ (a >> 14)) % ROUTED_MAX;
}

// The slot of `publisher`, or of the free slot where it would go (under routed_lock).
static size_t find_slot(const void *publisher) {
  size_t i = slot_of(publisher);
  while (routed[i].publisher != NULL && routed[i].publisher != publisher) i = (i + 1) % ROUTED_MAX;
  return i;
}

// The routing of `publisher`, or NULL.
static void *routing_of(const void *publisher) {
  pthread_mutex_lock(&routed_lock);
  void *routing = routed[find_slot(publisher)].routing;
  pthread_mutex_unlock(&routed_lock);
  return routing;
}

// Empties slot `i` and moves back the entries after it that it would hide (under routed_lock).
static void free_slot(size_t i) {
  routed[i].publisher = NULL, routed[i].routing = NULL;
  for (size_t j = (i + 1) % ROUTED_MAX; routed[j].publisher != NULL; j = (j + 1) % ROUTED_MAX) {
    size_t home = slot_of(routed[j].publisher);
    // j's entry stays where it is if its home lies cyclically in (i, j]
    if (i <= j ? (i < home && home <= j) : (i < home || home <= j)) continue;
    routed[i] = routed[j];
    routed[j].publisher = NULL, routed[j].routing = NULL;
    i = j;
  }
}

// `publisher` is (routing != NULL) or is no longer (NULL) a routed publisher; the routing it had
// before, if any, goes to the layer's release (an address that rcl reuses for another publisher
// forgets the routing of the one before).
static bool set_routing(const void *publisher, void *routing) {
  bool stored = routing == NULL;
  void *before = NULL;
  pthread_mutex_lock(&routed_lock);
  size_t i = find_slot(publisher);
  if (routed[i].publisher != NULL) {
    before = routed[i].routing;
    free_slot(i);
    // routed_count is read without the lock too (rcl_publish's quick test): stored atomically.
    __atomic_store_n(&routed_count, routed_count - 1, __ATOMIC_RELEASE);
    i = find_slot(publisher);
  }
  if (routing != NULL && routed_count < ROUTED_MAX - 1) {
    routed[i].publisher = publisher, routed[i].routing = routing;
    __atomic_store_n(&routed_count, routed_count + 1, __ATOMIC_RELEASE);
    stored = true;
  }
  pthread_mutex_unlock(&routed_lock);
  if (before != NULL) layer.release(before);
  return stored;
}

// What the guard routes, by topic: the verdict and the mark of the readers that ask for it.
static int feedback_judge(void **state, const uint8_t *data, uint32_t length,
                          const uint8_t *reader) {
  (void)state;
  return cft_feedback_verdict(data, length, reader);
}
static const struct cft_marked_verdict feedback_verdict = {feedback_judge, NULL,
                                                           cft_write_passes_unjudged, NULL, 0};
static const struct cft_marked_verdict status_verdict = {cft_status_judge, cft_status_forget,
                                                         cft_write_passes_unjudged, NULL, 0};
// A writer with no program-marked reader looks at its readers every PROGRAM_LOOKUP_MS at most: a
// reader not known yet passes, and its own process decides (it does so for every sample anyway).
#define PROGRAM_LOOKUP_MS 50
static const struct cft_marked_verdict program_verdict = {
    cft_program_judge, cft_program_forget, cft_write_passes_unjudged, cft_program_update,
    PROGRAM_LOOKUP_MS};
static const struct routed_kind {
  const char *what;
  const struct cft_marked_verdict *verdict;
  const char *reader_mark;
  bool (*is_topic)(const char *topic);
  const char *(*unroutable)(void);  // why not, or NULL
  void (*routed)(void);             // counts it
  long (*heartbeat_ms)(void);       // its writer's heartbeat period at most (0: Fast DDS's); NULL
  void (*heartbeat_set)(void);      // counts a writer given it
  bool failures_once;               // any publisher may be one: a failure is said once
} kinds[] = {
  {"feedback", &feedback_verdict, CFT_READER_MARK, cft_feedback_is_topic, cft_feedback_unroutable,
   cft_feedback_writer_routed, NULL, NULL, false},
  {"status", &status_verdict, CFT_STATUS_READER_MARK, cft_status_is_topic, cft_status_unroutable,
   cft_status_reader_kept, cft_status_heartbeat_ms, cft_status_heartbeat_set, false},
  {"samples", &program_verdict, CFT_PROGRAM_READER_MARK, cft_programs_is_topic,
   cft_programs_unroutable, cft_programs_writer_routed, NULL, NULL, true},
};
#define KINDS ((int)(sizeof kinds / sizeof kinds[0]))

// `publisher`, of `topic`, one of `kind`'s, in a process of Fast DDS 3, gets its samples routed,
// or says why not (once, for a kind with failures_once).
static bool failure_said[KINDS];
static void route(const void *publisher, const char *topic, int kind) {
  const struct routed_kind *k = &kinds[kind];
  const char *unroutable = k->unroutable();
  if (unroutable != NULL) {
    static int said[KINDS];
    if (CFT_FASTDDS3_PREFILTER && !__atomic_exchange_n(&said[kind], 1, __ATOMIC_ACQ_REL))
      cft_say("%s goes to every client as rmw_fastrtps sends it: %s", k->what, unroutable);
    return;
  }
  if (!layer_for(true)) return;
  void *writer = layer.datawriter(rcl.publisher_rmw_handle(publisher));
  int32_t error = -1;
  int32_t heartbeat_ms = k->heartbeat_ms != NULL ? (int32_t)k->heartbeat_ms() : 0;
  void *routing = writer != NULL ? layer.route_marked(writer, k->verdict, k->reader_mark,
                                                      CFT_WRITER_MARK, &heartbeat_ms, &error)
                                 : NULL;
  if (routing != NULL && set_routing(publisher, routing)) {
    k->routed();
    if (heartbeat_ms > 0) k->heartbeat_set();
  } else if (!k->failures_once || cft_first(&failure_said[kind])) {
    cft_say("the %s of %.200s goes to every reader: %s (%d)%s", k->what, topic,
            writer == NULL ? "it has no rmw_fastrtps_cpp writer"
            : routing == NULL ? "its DataWriter refused the prefilter or the mark"
                              : "too many routed publishers", (int)error,
            k->failures_once ? " (said once for all publishers)" : "");
  }
}

// A publisher that rcl made, in a process of Fast DDS 3, gets its samples routed: an action's
// feedback or status publisher to the readers that ask for their own goals', any other to the
// readers that mark a program.
static void publisher_created(const void *publisher) {
  if (__atomic_load_n(&routed_count, __ATOMIC_ACQUIRE) > 0) set_routing(publisher, NULL);
  if (rcl.topic == NULL || rcl.publisher_rmw_handle == NULL) return;
  const char *topic = rcl.topic(publisher);
  for (int kind = 0; kind < KINDS; kind++) {
    if (kinds[kind].is_topic(topic) && cft_loaded_family() == 1) {
      route(publisher, topic, kind);
      return;  // a writer has one prefilter
    }
  }
}

CFT_EXPORT int32_t rcl_publisher_init(void *publisher, const void *node, const void *type_support,
                                      const char *topic_name, const void *options);
int32_t rcl_publisher_init(void *publisher, const void *node, const void *type_support,
                           const char *topic_name, const void *options) {
  return init_endpoint(false, publisher, node, type_support, topic_name, options);
}

// A publisher that rcl destroys gives its routing back to the layer.
CFT_EXPORT int32_t rcl_publisher_fini(void *publisher, void *node);
int32_t rcl_publisher_fini(void *publisher, void *node) {
  pthread_once(&rcl_once, resolve_rcl);
  if (rcl.publisher_fini == NULL) return missing(PUBLISHER_FINI);
  if (__atomic_load_n(&routed_count, __ATOMIC_ACQUIRE) > 0) set_routing(publisher, NULL);
  return rcl.publisher_fini(publisher, node);
}

// Before a write of a routed publisher, on the publishing thread, outside Fast DDS: the
// layer learns which of its writer's readers carry the mark.
CFT_EXPORT int32_t rcl_publish(const void *publisher, const void *ros_message, void *allocation);
int32_t rcl_publish(const void *publisher, const void *ros_message, void *allocation) {
  pthread_once(&rcl_once, resolve_rcl);
  if (rcl.publish == NULL) return missing(PUBLISH);
  void *routing = __atomic_load_n(&routed_count, __ATOMIC_ACQUIRE) > 0 ? routing_of(publisher)
                                                                        : NULL;
  if (routing != NULL) {
    void *writer = layer.datawriter(rcl.publisher_rmw_handle(publisher));
    if (writer != NULL) layer.marked_readers(routing, writer);
  }
  return rcl.publish(publisher, ros_message, allocation);
}

// ---- the C API, for ctypes -----------------------------------------------------------------------------
// The Fast DDS 3 layer's state: "on: ..." or "off: <why>".
CFT_EXPORT const char *cft_guard_prefilter_state(void) {
  if (!cft_replies_wanted() && !cft_feedback_wanted())
    return "off: CFT_GUARD_REPLIES and CFT_GUARD_FEEDBACK are off";
  return __atomic_load_n(&layer_state, __ATOMIC_ACQUIRE);
}
