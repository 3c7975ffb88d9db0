// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// Which remote writers filter for the library's filter classes, in a reader's process; and which
// content filter class remote readers have, for `cft-action action info`.
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
//
// A reader's filter is in its discovery data too: Fast DDS sends its ContentFilterProperty in SEDP
// and keeps it in the ReaderProxyData that rmw's listener is handed, but rmw passes only the GID,
// names, type hash and QoS on. Between the two calls above, rmw calls
//   rmw_fastrtps_shared_cpp::create_rmw_gid(identifier, proxyData.guid())
// through its own PLT (an exported function of that library), with a reference to the data's
// m_guid. That third slot is redirected too: on the discovery thread, between parse and
// add_entity, the GUID references it is given are kept, and add_entity of a reader finds the one
// that holds the reader's GID: the data's m_guid. The filter is then read at the headers' offsets
// from m_guid on (_fastdds_layout.h), which hold on apt's SECURITY=ON build too (its masks come
// before m_guid), after the same check as the guard's: m_key holds the GUID too. Only the class
// name is kept (empty: no filter). rmw ignores CHANGED_QOS_READER, so a filter changed in place
// after discovery is not seen; the first filter recreates the reader, which is.
#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdint.h>
#include <string.h>

#include "_fastdds_layout.h"
#include "_filter_class.h"
#include "_patch.h"

#define EXPORT __attribute__((visibility("default")))

#define RMW_SHARED_SONAME "librmw_fastrtps_shared_cpp.so"
#define PARSE "_ZN14rmw_dds_common30parse_type_hash_from_user_dataEPKhmR18rosidl_type_hash_s"
#define ADD_ENTITY                                                                           \
  "_ZN14rmw_dds_common10GraphCache10add_entityERK9rmw_gid_sRKNSt7__cxx1112basic_stringIcSt11" \
  "char_traitsIcESaIcEEESB_RK18rosidl_type_hash_sS3_RK17rmw_qos_profile_sb"
#define CREATE_GID "_ZN23rmw_fastrtps_shared_cpp14create_rmw_gidEPKcRKN8eprosima8fastrtps4rtps6GUID_tE"

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

typedef struct gid (*create_gid_fn)(const char *identifier, const uint8_t *guid);

static parse_fn real_parse;
static add_entity_fn real_add_entity;
static __thread bool parsed_mark;  // the last USER_DATA parsed on this thread held the mark
// Between parse and add_entity on this thread: the GUID references create_rmw_gid was given, where
// the readers' filters are read (Fast DDS 2's layout, install_reader_filters).
#define READER_FILTERS_KNOWN (CFT_LAYOUT_KNOWN && CFT_LAYOUT_VERSION_MAJOR == 2)
#define GUID_REFS 4
static __thread bool discovering;
#if READER_FILTERS_KNOWN
static __thread const uint8_t *guid_refs[GUID_REFS];
#endif
static __thread unsigned guid_ref_count;

// The marked writers seen, a ring: a writer's GID is never reused, and one that is gone only
// takes a slot until it is overwritten.
#define MARKED_SLOTS 4096
static uint8_t marked[MARKED_SLOTS][GID_SIZE];
static unsigned marked_count;  // written so far (the ring's next slot is marked_count % SLOTS)
static pthread_mutex_t marked_lock = PTHREAD_MUTEX_INITIALIZER;

// The readers seen and their filter class ("": none), a ring as `marked`.
#define CLASS_NAME_MAX 64
struct reader_filter_class {
  uint8_t gid[GID_SIZE];
  char class_name[CLASS_NAME_MAX];
};
static struct reader_filter_class readers[MARKED_SLOTS];
static unsigned reader_count;
static char reader_error[256];  // why readers' filters are not read: set once, "" while they are

static int32_t parse(const uint8_t *user_data, size_t size, void *type_hash) {
  discovering = true;
  guid_ref_count = 0;
  parsed_mark = user_data != NULL &&
                memmem(user_data, size, CFT_WRITER_MARK, sizeof CFT_WRITER_MARK - 1) != NULL;
  return real_parse(user_data, size, type_hash);
}

#if READER_FILTERS_KNOWN
static create_gid_fn real_create_gid;
static struct gid create_gid(const char *identifier, const uint8_t *guid) {
  if (discovering && guid_ref_count < GUID_REFS) guid_refs[guid_ref_count++] = guid;
  return real_create_gid(identifier, guid);
}
#endif

#if CFT_LAYOUT_KNOWN
// The class name of the filter in the discovery data whose m_guid is at `guid` ("" for none) in
// `out`; false when the data fails a check.
static bool filter_class_at(const uint8_t *guid, char *out) {
  if (memcmp(guid - RPD_GUID + RPD_KEY, guid, GID_SIZE) != 0) return false;
  const uint8_t *name = guid - RPD_GUID + RPD_CONTENT_FILTER + CFP_CLASS_NAME;
  size_t length;
  memcpy(&length, name + STRING255_LENGTH, sizeof length);
  if (length >= CLASS_NAME_MAX || name[length] != '\0' || memchr(name, '\0', length) != NULL)
    return false;
  memcpy(out, name, length + 1);
  return true;
}
#else
static bool filter_class_at(const uint8_t *guid, char *out) {
  (void)guid, (void)out;
  return false;
}
#endif

// Records the filter class of the reader `gid` from the GUID references kept since parse. The
// first failure (reader_error) ends the reading for the process.
// rmw passes create_rmw_gid two references there: the data's m_guid, and a temporary GUID_t on
// its stack made from the data's participant key, which the remote participant announces as it
// likes. When both hold the reader's GID, which one is m_guid cannot be told: the reader is not
// read (and reading goes on for the others), rather than reading rmw's stack as discovery data.
static void note_reader(const struct gid *gid) {
  const uint8_t *guid = NULL;
#if READER_FILTERS_KNOWN
  int holding = 0;
  for (unsigned i = 0; i < guid_ref_count; i++)
    if (memcmp(guid_refs[i], gid->data, GID_SIZE) == 0) guid = guid_refs[i], holding++;
  if (holding > 1) return;
#endif
  pthread_mutex_lock(&marked_lock);
  struct reader_filter_class *slot = &readers[reader_count % MARKED_SLOTS];
  if (reader_error[0] != '\0') {
    // read no more
  } else if (guid == NULL) {
    snprintf(reader_error, sizeof reader_error,
             "rmw did not pass the reader's GUID to create_rmw_gid before add_entity");
  } else if (!filter_class_at(guid, slot->class_name)) {
    snprintf(reader_error, sizeof reader_error,
             "a reader's discovery data is not in the layout of %s", CFT_LAYOUT_SOURCE);
  } else {
    memcpy(slot->gid, gid->data, GID_SIZE);
    reader_count++;
  }
  pthread_mutex_unlock(&marked_lock);
}

static bool add_entity(void *self, const struct gid *gid, const void *topic_name,
                       const void *type_name, const void *type_hash, const struct gid *participant,
                       const void *qos, bool is_reader) {
  if (parsed_mark && !is_reader && gid != NULL) {
    pthread_mutex_lock(&marked_lock);
    memcpy(marked[marked_count++ % MARKED_SLOTS], gid->data, GID_SIZE);
    pthread_mutex_unlock(&marked_lock);
  }
  if (discovering && is_reader && gid != NULL) note_reader(gid);
  parsed_mark = discovering = false;
  guid_ref_count = 0;
  return real_add_entity(self, gid, topic_name, type_name, type_hash, participant, qos, is_reader);
}

static struct cft_install installed = CFT_INSTALL_INIT;

// The readers' filters, where the loaded rmw_fastrtps has the Fast DDS 2 create_rmw_gid (its
// mangled name names eprosima::fastrtps::rtps::GUID_t) and this library has the layout of the
// Fast DDS 2 headers; else reader_error says why they are not read.
static void install_reader_filters(void *library) {
#if READER_FILTERS_KNOWN
  real_create_gid = (create_gid_fn)dlsym(library, CREATE_GID);
  if (real_create_gid == NULL)
    snprintf(reader_error, sizeof reader_error, "not found: %s", CREATE_GID);
  else if (cft_patch_got(RMW_SHARED_SONAME, CREATE_GID, (void *)real_create_gid,
                         (void *)create_gid) != 1)
    snprintf(reader_error, sizeof reader_error, "cannot redirect the PLT slot of %s", CREATE_GID);
#else
  (void)library;
  snprintf(reader_error, sizeof reader_error, "no Fast DDS 2 layout: %s", CFT_LAYOUT_SOURCE);
#endif
}

static int install(struct cft_install *once) {
  static const char *const names[] = {PARSE, ADD_ENTITY};
  void *resolved[2];
  int status;
  void *library = cft_resolve(once, RMW_SHARED_SONAME, names, 2, resolved, &status);
  if (library == NULL) return status;
  real_parse = (parse_fn)resolved[0];
  real_add_entity = (add_entity_fn)resolved[1];
  // Before add_entity is redirected: it may run on the discovery thread at once, and then looks
  // for create_rmw_gid's references.
  install_reader_filters(library);
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

// The filter class of the reader with this GID (16 bytes) in `out` (`size` bytes; "" for none):
// 1 if it was discovered, 0 if not (or its data could not be read: cft_reader_filters_error).
EXPORT int cft_reader_filter_class(const uint8_t *gid, char *out, size_t size) {
  int found = 0;
  pthread_mutex_lock(&marked_lock);
  unsigned n = reader_count < MARKED_SLOTS ? reader_count : MARKED_SLOTS;
  // The newest first: a GID is not reused, but a slot may have been overwritten.
  for (unsigned i = n; i-- > 0 && !found;) {
    const struct reader_filter_class *slot = &readers[(reader_count - n + i) % MARKED_SLOTS];
    if (memcmp(slot->gid, gid, GID_SIZE) == 0 && size > 0) {
      snprintf(out, size, "%s", slot->class_name);
      found = 1;
    }
  }
  pthread_mutex_unlock(&marked_lock);
  return found;
}

// Why readers' filters are not read ("" while they are), once cft_writer_marks_install returned 0.
EXPORT const char *cft_reader_filters_error(void) {
  static char copy[sizeof reader_error];
  pthread_mutex_lock(&marked_lock);
  memcpy(copy, reader_error, sizeof copy);
  pthread_mutex_unlock(&marked_lock);
  return copy;
}
