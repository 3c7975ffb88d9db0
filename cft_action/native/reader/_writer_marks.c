// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// Which remote writers filter for the library's filter classes, in a reader's process.
//
// A guarded writer keeps the readers of those classes itself and writes no filter signature for
// them (_guard_filter.c), so nothing in a sample tells a reader that the writer filtered it. The
// writer's discovery data does: the guard appends CFT_WRITER_MARK to its USER_DATA
// (_guard_writer_qos.c). rmw_fastrtps reads every discovered endpoint's USER_DATA in its
// participant listener, one endpoint at a time on the discovery thread:
//   rmw_dds_common::parse_type_hash_from_user_data(data, size, hash), then
//   rmw_dds_common::GraphCache::add_entity(gid, topic, type, hash, participant, qos, is_reader)
// both in librmw_dds_common, called through the PLT of librmw_fastrtps_shared_cpp. Their two PLT
// slots are redirected here: the first notes whether the USER_DATA holds the mark, the second
// records the endpoint's GID when it is a marked writer. Only endpoints discovered after the
// redirection are seen, so cft_writer_marks_install says whether it came before any participant
// existed (the caller knows; see _rcl.py).
#define _GNU_SOURCE
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <string.h>

#include "_filter_class.h"
#include "_patch.h"

#define EXPORT __attribute__((visibility("default")))

#define RMW_SHARED_SONAME "librmw_fastrtps_shared_cpp.so"
#define PARSE "_ZN14rmw_dds_common30parse_type_hash_from_user_dataEPKhmR18rosidl_type_hash_s"
#define ADD_ENTITY                                                                           \
  "_ZN14rmw_dds_common10GraphCache10add_entityERK9rmw_gid_sRKNSt7__cxx1112basic_stringIcSt11" \
  "char_traitsIcESaIcEEESB_RK18rosidl_type_hash_sS3_RK17rmw_qos_profile_sb"

// rmw_gid_t of rmw/types.h: the implementation's identifier, then RMW_GID_STORAGE_SIZE (16) bytes,
// which rmw_fastrtps fills with the endpoint's GUID (tests/test_signatures.py checks the size
// against rclpy's endpoint GIDs).
#define GID_SIZE 16
struct gid {
  const char *implementation_identifier;
  uint8_t data[GID_SIZE];
};

typedef int32_t (*parse_fn)(const uint8_t *user_data, size_t size, void *type_hash);
typedef bool (*add_entity_fn)(void *self, const struct gid *gid, const void *topic_name,
                              const void *type_name, const void *type_hash,
                              const struct gid *participant, const void *qos, bool is_reader);

static parse_fn real_parse;
static add_entity_fn real_add_entity;
static __thread bool parsed_mark;  // the last USER_DATA parsed on this thread held the mark

// The marked writers seen, a ring: a writer's GID is never reused, and one that is gone only
// takes a slot until it is overwritten.
#define MARKED_SLOTS 4096
static uint8_t marked[MARKED_SLOTS][GID_SIZE];
static unsigned marked_count;  // written so far (the ring's next slot is marked_count % SLOTS)
static pthread_mutex_t marked_lock = PTHREAD_MUTEX_INITIALIZER;

static int32_t parse(const uint8_t *user_data, size_t size, void *type_hash) {
  parsed_mark = user_data != NULL &&
                memmem(user_data, size, CFT_WRITER_MARK, sizeof CFT_WRITER_MARK - 1) != NULL;
  return real_parse(user_data, size, type_hash);
}

static bool add_entity(void *self, const struct gid *gid, const void *topic_name,
                       const void *type_name, const void *type_hash, const struct gid *participant,
                       const void *qos, bool is_reader) {
  if (parsed_mark && !is_reader && gid != NULL) {
    pthread_mutex_lock(&marked_lock);
    memcpy(marked[marked_count++ % MARKED_SLOTS], gid->data, GID_SIZE);
    pthread_mutex_unlock(&marked_lock);
  }
  parsed_mark = false;
  return real_add_entity(self, gid, topic_name, type_name, type_hash, participant, qos, is_reader);
}

static struct cft_install installed = CFT_INSTALL_INIT;

static int install(struct cft_install *once) {
  static const char *const names[] = {PARSE, ADD_ENTITY};
  void *resolved[2];
  int status;
  if (cft_resolve(once, RMW_SHARED_SONAME, names, 2, resolved, &status) == NULL) return status;
  real_parse = (parse_fn)resolved[0];
  real_add_entity = (add_entity_fn)resolved[1];
  if (cft_patch_got(RMW_SHARED_SONAME, PARSE, (void *)real_parse, (void *)parse) != 1)
    return cft_install_fail(once, -3, "cannot redirect the PLT slot of", PARSE);
  if (cft_patch_got(RMW_SHARED_SONAME, ADD_ENTITY, (void *)real_add_entity, (void *)add_entity) != 1)
    return cft_install_fail(once, -4, "cannot redirect the PLT slot of", ADD_ENTITY);
  return 0;
}

// 0 once the marks are read from every endpoint discovered from now on, < 0 if that cannot be
// arranged (cft_writer_marks_error says why). Later calls return the first result.
EXPORT int cft_writer_marks_install(void) { return cft_install_once(&installed, install); }

EXPORT const char *cft_writer_marks_error(void) { return installed.error; }

// 1 if the writer with this GID (16 bytes) was discovered with the mark, else 0.
EXPORT int cft_writer_is_marked(const uint8_t *gid) {
  int found = 0;
  pthread_mutex_lock(&marked_lock);
  unsigned n = marked_count < MARKED_SLOTS ? marked_count : MARKED_SLOTS;
  for (unsigned i = 0; i < n && !found; i++) found = memcmp(marked[i], gid, GID_SIZE) == 0;
  pthread_mutex_unlock(&marked_lock);
  return found;
}
