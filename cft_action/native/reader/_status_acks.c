// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// An action client's status reader answers a HEARTBEAT at once instead of 5 ms later.
//
// A guarded server (native/guard/_guard_status.c) sends a client's status reader the samples that
// change its goals, and also every later sample until the reader has acknowledged the last one it
// was passed: the status writer keeps one sample, so a sample replaced before the reader's
// acknowledgement may never have arrived, and the next one must carry its news (an "owed"
// sample). A Fast DDS 2.14 reader acknowledges `heartbeatResponseDelay` after the first HEARTBEAT
// that finds its timer idle (5 ms by default; WriterProxy::process_heartbeat, whose
// TimedEvent::restart_timer leaves a running timer alone). While a server's goals change status
// faster than that, every owed sample is replaced before it is acknowledged, and the reader is
// passed the whole burst: N = 16 clients x 4 goals received 35-181 status samples each in seven
// runs, 18-138 with the delay at 0 (`python -m benchmarks.status --parts grid --clients 16
// --goals 4 --configs client`), of the 12 that change their goals. rmw gives no way to set a
// reader's times; StatefulReader::updateTimes (exported, public) sets them, taking the reader's
// mutex, for the reader and its matched writers.
//
// The reader is the one that rmw_fastrtps registers with a content filter of CFT_STATUS_CLASS on an
// `rt/.../_action/status` topic (the library's status filter, _status_trim.c): seen as it is
// registered (_registration.c), before any writer is matched. Checks, each of which leaves the
// reader as Fast DDS made it (and says why, cft_status_acks_refused):
// - it is a StatefulReader (its vtable pointer is that class's, exported by libfastrtps);
// - its times_ member (the offset from the headers, _fastdds_layout.h) holds a ReaderTimes vtable
//   pointer at exactly one place at most 64 bytes past the headers' offset (a security build's
//   EndpointAttributes are larger), and a response delay of at most 1 s there. The vtable is told
//   by its symbol's name (dladdr): ReaderTimes's destructor is inline, so every library that
//   constructs one may carry a copy of it, and the constructor in libfastrtps binds to the first
//   copy in the process's lookup order, not necessarily libfastrtps's own.
// The copy given to updateTimes is those bytes (so the vtable pointer is a real one) with the
// delay at STATUS_ACK_DELAY.
//
// What it costs: an acknowledgement per HEARTBEAT that finds the timer idle, instead of one per
// 5 ms at most; a few tens of bytes each, from the client to the server.
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "_endpoint_times.h"
#include "_fastdds_layout.h"
#include "_filter_class.h"
#include "_registration.h"

#define EXPORT __attribute__((visibility("default")))

#define FASTRTPS_SONAME "libfastrtps.so.2.14"
#define UPDATE_TIMES "_ZN8eprosima8fastrtps4rtps14StatefulReader11updateTimesERKNS1_11ReaderTimesE"
#define READER_VTABLE "_ZTVN8eprosima8fastrtps4rtps14StatefulReaderE"
#define TIMES_VTABLE "_ZTVN8eprosima8fastrtps4rtps11ReaderTimesE"
#define STATUS_SUFFIX "/_action/status"
#define STATUS_ACK_DELAY_NS 0

typedef bool (*update_times_fn)(void *reader, const void *times);

static struct cft_install installed = CFT_INSTALL_INIT;
static __thread int adjusted_here;   // on this thread, since cft_status_acks_taken
static __thread char refused[160];   // why the last status reader on this thread was left alone

#if CFT_LAYOUT_KNOWN
static update_times_fn update_times;
static uintptr_t reader_vptr;

static bool ends_with(const char *text, const char *suffix) {
  size_t length = strnlen(text, STRING255_LENGTH), tail = strlen(suffix);
  return length < STRING255_LENGTH && length > tail && strcmp(text + length - tail, suffix) == 0;
}

// The address of the reader's times_, or 0 after saying why in `refused`. Every word read lies in
// the StatefulReader object that the headers describe (SR_SIZE), which a larger build only extends.
static uintptr_t times_member(uintptr_t reader) {
  if (*(const uintptr_t *)reader != reader_vptr) {
    snprintf(refused, sizeof refused, "the status reader is not a StatefulReader");
    return 0;
  }
  int found;
  uintptr_t member = cft_endpoint_times(reader, SR_SIZE, SR_TIMES, RT_SIZE, TIMES_VTABLE, &found);
  if (member == 0) {
    snprintf(refused, sizeof refused,
             "the status reader's times are not at exactly one offset near the headers' (%d "
             "found): the loaded Fast DDS has another StatefulReader layout", found);
    return 0;
  }
  struct cft_duration delay;
  memcpy(&delay, (const void *)(member + RT_RESPONSE_DELAY), sizeof delay);
  if (delay.seconds < 0 || delay.seconds > 1 || delay.nanosec >= 1000000000u) {
    snprintf(refused, sizeof refused, "the status reader's response delay does not read as one");
    return 0;
  }
  return member;
}

static void registering(void *reader, const char *topic_name, const void *content_filter) {
  if (content_filter == NULL ||
      strncmp((const char *)content_filter + CFP_CLASS_NAME, CFT_STATUS_CLASS,
              sizeof CFT_STATUS_CLASS) != 0 ||
      !ends_with(topic_name, STATUS_SUFFIX))
    return;
  refused[0] = '\0';
  uintptr_t member = times_member((uintptr_t)reader);
  if (member == 0) return;
  _Alignas(16) unsigned char times[RT_SIZE];
  memcpy(times, (const void *)member, sizeof times);
  struct cft_duration delay = {0, STATUS_ACK_DELAY_NS};
  memcpy(times + RT_RESPONSE_DELAY, &delay, sizeof delay);
  update_times(reader, times);
  adjusted_here++;
}
#endif

static int install(struct cft_install *once) {
#if !CFT_LAYOUT_KNOWN
  return cft_install_fail(once, -5, "no Fast DDS layout at build time", CFT_LAYOUT_SOURCE);
#else
  static const char *const names[] = {UPDATE_TIMES, READER_VTABLE};
  void *resolved[2];
  int status;
  if (cft_resolve(once, FASTRTPS_SONAME, names, 2, resolved, &status) == NULL) return status;
  update_times = (update_times_fn)resolved[0];
  reader_vptr = (uintptr_t)resolved[1] + CFT_VTABLE_START;
  return cft_registration_install(once, registering);
#endif
}

// 0 once the status readers registered from now on answer HEARTBEATs at once; < 0 if that cannot
// be arranged (cft_status_acks_error says why). Later calls return the first result.
EXPORT int cft_status_acks_install(void) { return cft_install_once(&installed, install); }

EXPORT const char *cft_status_acks_error(void) { return installed.error; }

// How many status readers this thread registered since the last call that were given the delay
// (and resets it); why the last one was left alone, in cft_status_acks_refused ('' if it was not).
EXPORT int cft_status_acks_taken(void) {
  int taken = adjusted_here;
  adjusted_here = 0;
  return taken;
}

EXPORT const char *cft_status_acks_refused(void) { return refused; }
