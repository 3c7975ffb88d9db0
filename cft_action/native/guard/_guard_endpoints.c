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
// every client as rmw_fastrtps sends it, and the first action service says once why
// (cft_guard_prefilter_state too). rcl's definitions are found in the loaded librcl (ROS loads it
// in a local scope: RTLD_NEXT does not see it). CFT_GUARD_REPLIES=off (or 0) leaves every service
// as rcl made it.

#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "_fastdds_layout.h"
#include "_guard_families.h"
#include "_guard_log.h"
#include "_guard_replies.h"
#include "fastdds3/_prefilter.h"

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
#define RESPONSE_WRITER "_ZN16rmw_fastrtps_cpp23get_response_datawriterEP13rmw_service_s"
// This library's file name starts with GUARD_NAME; the layer's, in the same folder, with
// LAYER_NAME, the rest being the same (the Python extension suffix).
#define GUARD_NAME "_cftguard"
#define LAYER_NAME "_cftguard_fastdds3"

typedef int32_t (*service_init_fn)(void *service, const void *node, const void *type_support,
                                   const char *service_name, const void *options);
typedef void *(*handle_fn)(const void *object);
typedef const char *(*name_fn)(const void *object);

static struct {
  service_init_fn init;
  handle_fn rmw_handle;
  name_fn name;
} rcl;
static pthread_once_t rcl_once = PTHREAD_ONCE_INIT;
static void resolve_rcl(void) {
  rcl.init = (service_init_fn)cft_guard_loaded_symbol(SERVICE_INIT, "librcl");
  rcl.rmw_handle = (handle_fn)cft_guard_loaded_symbol(SERVICE_RMW_HANDLE, "librcl");
  rcl.name = (name_fn)cft_guard_loaded_symbol(SERVICE_NAME, "librcl");
}

// ---- the Fast DDS 3 layer -----------------------------------------------------------------------
static char layer_state[640] = "off: no action service created yet";
static struct {
  cft_fastdds3_route_replies_fn route_replies;
  handle_fn response_writer;
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
  if (!CFT_FASTDDS3_PREFILTER) {
    snprintf(why, sizeof why, "not built (%s)", CFT_FASTDDS3_SOURCE);
  } else if (__atomic_load_n(&f->state, __ATOMIC_ACQUIRE) != CFT_GUARD_ACTIVE) {
    snprintf(why, sizeof why, "the guard does not lock this Fast DDS 3 (%.400s)", f->reason);
  } else if (dlopen(CFT_FASTDDS3_SONAME, RTLD_LAZY | RTLD_NOLOAD) == NULL) {
    snprintf(why, sizeof why, "the loaded Fast DDS is not %s, the one the layer was built with",
             CFT_FASTDDS3_SONAME);
  } else if ((layer.response_writer = (handle_fn)cft_guard_loaded_symbol(
                  RESPONSE_WRITER, "rmw_fastrtps_cpp")) == NULL) {
    snprintf(why, sizeof why, "no rmw_fastrtps_cpp::get_response_datawriter is loaded (another "
             "rmw implementation)");
  } else if (!layer_path(path, sizeof path)) {
    snprintf(why, sizeof why, "the guard library's file name does not start with %s", GUARD_NAME);
  } else {
    // Kept open for the process's life: the prefilters' code is in it.
    void *handle = dlopen(path, RTLD_LAZY | RTLD_LOCAL);
    layer.route_replies = handle != NULL ? (cft_fastdds3_route_replies_fn)dlsym(
                                               handle, CFT_FASTDDS3_ROUTE_REPLIES) : NULL;
    if (layer.route_replies == NULL)
      snprintf(why, sizeof why, "cannot load %.250s: %.150s", path, dlerror());
  }
  if (why[0] != '\0') {
    snprintf(layer_state, sizeof layer_state, "off: %s", why);
    cft_say("the Fast DDS 3 layer is off: %s; replies go to every client", why);
  } else {
    snprintf(layer_state, sizeof layer_state, "on: %.250s, built with %.300s", path,
             CFT_FASTDDS3_SOURCE);
  }
}

// A service that rcl made: an action's, in a process of Fast DDS 3, gets its replies routed.
static void service_created(const void *service) {
  if (cft_loaded_family() != 1 || !cft_replies_wanted() || rcl.name == NULL ||
      rcl.rmw_handle == NULL)
    return;
  const char *name = rcl.name(service);
  if (!cft_replies_is_action_service(name)) return;
  pthread_once(&layer_once, load_layer);
  if (layer.route_replies == NULL) return;
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
int32_t rcl_service_init(void *service, const void *node, const void *type_support,
                         const char *service_name, const void *options) {
  pthread_once(&rcl_once, resolve_rcl);
  if (rcl.init == NULL) {
    cft_say("no rcl_service_init after the guard's: a service cannot be created");
    return 1;  // RCL_RET_ERROR
  }
  int32_t ret = rcl.init(service, node, type_support, service_name, options);
  if (ret == 0) service_created(service);
  return ret;
}

// ---- the C API, for ctypes -----------------------------------------------------------------------------
// The Fast DDS 3 layer's state: "on: ..." or "off: <why>".
CFT_EXPORT const char *cft_guard_prefilter_state(void) {
  return cft_replies_wanted() ? layer_state : "off: CFT_GUARD_REPLIES is off";
}
