// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// libFuzzer harness of what a client's process reads from each discovered endpoint
// (cft_action/native/reader/_writer_marks.c): a remote endpoint's USER_DATA, searched for
// CFT_WRITER_MARK (a guarded writer's), and a remote reader's filter class from its
// ContentFilterProperty in the ReaderProxyData that rmw_fastrtps's listener is handed, found
// through the GUID references rmw passes to create_rmw_gid between parse and add_entity.
// rmw makes two GIDs there (custom_participant_info.hpp, on_*_discovery): of proxyData.guid(), and of
// a temporary GUID_t made from the data's participant key, which the remote side announces too.
// Input: the USER_DATA (a 2-byte little-endian length and its bytes), a byte of flags (USER_DATA
// absent, which GID is made first, rmw reports a GID no reference holds, reader or writer), the
// participant key (16 bytes), the reader's discovery data (fuzz_rpd_read in fuzz_common.h), and
// a byte: the size of the caller's class name buffer.
//
// The library's file is compiled into this one: its three hooks (parse, create_gid, add_entity)
// are what rmw_fastrtps's PLT slots call, and each input starts with empty rings.
#include "_writer_marks.c"  // NOLINT: the real source, not a copy

#include "fuzz_common.h"

// What the hooks forward to: rmw_dds_common's and rmw_fastrtps_shared_cpp's own.
static int32_t rmw_parse(const uint8_t *user_data, size_t size, void *type_hash) {
  (void)user_data, (void)size, (void)type_hash;
  return 0;
}
static bool rmw_add_entity(void *self, const struct gid *gid, const void *topic_name,
                           const void *type_name, const void *type_hash,
                           const struct gid *participant, const void *qos, bool is_reader) {
  (void)self, (void)gid, (void)topic_name, (void)type_name, (void)type_hash, (void)participant;
  (void)qos, (void)is_reader;
  return true;
}
static struct gid rmw_create_gid(const char *identifier, const uint8_t *guid) {
  struct gid gid = {identifier, {0}};
  memcpy(gid.data, guid, GID_SIZE);
  return gid;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  real_parse = rmw_parse;
  real_add_entity = rmw_add_entity;
  real_create_gid = rmw_create_gid;
  reader_error[0] = '\0';
  marked_count = reader_count = 0;
  struct fuzz_in in = {data, size};
  size_t user_data_size;
  uint8_t *user_data = fuzz_sample(&in, &user_data_size);
  uint8_t flags = fuzz_byte(&in);
  uint8_t *participant = malloc(16);  // the temporary GUID_t, exactly its size
  if (participant == NULL) abort();
  fuzz_bytes(&in, participant, 16);
  struct fuzz_rpd rpd;
  uint8_t guid[16];
  fuzz_rpd_read(&rpd, &in, guid);
  size_t out_size = fuzz_byte(&in) % 80;
  // rmw's listener: parse the USER_DATA, make the GID of the data's m_guid, add the entity.
  (void)parse(flags & 1 ? NULL : user_data, user_data_size, NULL);
  // The order in which the two arguments of add_entity are evaluated is the compiler's.
  if (flags & 2) (void)create_gid("rmw_fastrtps_cpp", participant);
  struct gid gid = create_gid("rmw_fastrtps_cpp", rpd.info + RPD_GUID + rpd.shift);
  if (!(flags & 2)) (void)create_gid("rmw_fastrtps_cpp", participant);
  if (flags & 4) {  // a GID that no reference holds: never rmw's, but the library checks it
    gid.data[15] ^= 1;
    if (memcmp(gid.data, participant, 16) == 0) gid.data[14] ^= 1;
  }
  bool is_reader = (flags & 8) != 0;
  (void)add_entity(NULL, &gid, NULL, NULL, NULL, NULL, NULL, is_reader);
  int marked = cft_writer_is_marked(gid.data);
  if (marked != (!is_reader && !(flags & 1) &&
                 memmem(user_data, user_data_size, CFT_WRITER_MARK, strlen(CFT_WRITER_MARK)) != NULL))
    abort();
  char *out = malloc(out_size ? out_size : 1);
  if (out == NULL) abort();
  (void)cft_reader_filter_class(gid.data, out, out_size);
  (void)cft_reader_filters_error();
  free(out);
  fuzz_rpd_free(&rpd);
  free(participant);
  free(user_data);
  return 0;
}
