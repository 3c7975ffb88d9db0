// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// See _registration.h. RTPSParticipant::registerReader, which DataReaderImpl::enable calls through
// libfastrtps's PLT, is redirected once per process; the redirection shows each reader to the parts
// and then calls the real member. The reader is constructed, its attributes (times, filter
// member) are set, and no writer is matched yet.
#define _GNU_SOURCE
#include <pthread.h>
#include <stdbool.h>
#include <stdio.h>

#include "_fastdds_layout.h"
#include "_registration.h"

#define FASTRTPS_SONAME "libfastrtps.so.2.14"
#define REGISTER_READER                                                                      \
  "_ZN8eprosima8fastrtps4rtps15RTPSParticipant14registerReaderEPNS1_10RTPSReaderERKNS0_15" \
  "TopicAttributesERKNS_7fastdds3dds9ReaderQosEPKNS8_4rtps21ContentFilterPropertyE"

typedef bool (*register_reader_fn)(void *self, void *reader, const void *topic, const void *qos,
                                   const void *content_filter);

static struct cft_install installed = CFT_INSTALL_INIT;

// The parts' functions, in the order they installed; a slot is written before the count that
// covers it (release), and never changed.
#define MAX_PARTS 4
static cft_registering_fn parts[MAX_PARTS];
static int part_count;
static pthread_mutex_t parts_lock = PTHREAD_MUTEX_INITIALIZER;

#if CFT_LAYOUT_KNOWN
static register_reader_fn real_register_reader;

static bool register_reader(void *self, void *reader, const void *topic, const void *qos,
                            const void *content_filter) {
  if (reader != NULL) {
    const char *name = (const char *)topic + TOPIC_NAME;  // a fixed_string<255>'s characters
    int count = __atomic_load_n(&part_count, __ATOMIC_ACQUIRE);
    for (int i = 0; i < count; i++) parts[i](reader, name, content_filter);
  }
  return real_register_reader(self, reader, topic, qos, content_filter);
}
#endif

static int install(struct cft_install *once) {
#if !CFT_LAYOUT_KNOWN
  return cft_install_fail(once, -5, "no Fast DDS layout at build time", CFT_LAYOUT_SOURCE);
#else
  static const char *const names[] = {REGISTER_READER};
  void *resolved[1];
  int status;
  if (cft_resolve(once, FASTRTPS_SONAME, names, 1, resolved, &status) == NULL) return status;
  real_register_reader = (register_reader_fn)resolved[0];
  if (cft_patch_got(FASTRTPS_SONAME, REGISTER_READER, resolved[0], (void *)register_reader) != 1)
    return cft_install_fail(once, -3, "no free PLT slot in " FASTRTPS_SONAME " for",
                            REGISTER_READER);
  return 0;
#endif
}

int cft_registration_install(struct cft_install *once, cft_registering_fn part) {
  int status = cft_install_once(&installed, install);
  if (status < 0) {
    snprintf(once->error, sizeof once->error, "%s", installed.error);
    return status;
  }
  pthread_mutex_lock(&parts_lock);
  int count = part_count;
  if (count < MAX_PARTS) {
    parts[count] = part;
    __atomic_store_n(&part_count, count + 1, __ATOMIC_RELEASE);
  }
  pthread_mutex_unlock(&parts_lock);
  return count < MAX_PARTS ? status : cft_install_fail(once, -6, "too many parts", "registration");
}
