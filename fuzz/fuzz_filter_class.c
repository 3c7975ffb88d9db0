// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// libFuzzer harness of the library's content filter classes as Fast DDS calls them
// (cft_action/native/_filter_class.c): IContentFilterFactory::create_content_filter with a
// class name, an expression (a remote reader's, from its discovery data, at a guarded writer; a
// local reader's at a client) and its updates, then IContentFilter::evaluate on serialized samples
// from any writer: a FeedbackMessage's goal UUID (CFT_ACTION_UUID), a ParameterEvent's node name
// (CFT_ACTION_NODE), the writer's GUID around the payload (CFT_ACTION_RATE), a GoalStatusArray
// (CFT_ACTION_STATUS, the client's own class, reader/_status_trim.c).
// Input: NUL-ended: the class name, the expression, the update's expression; then operations,
// each an opcode byte, a writer byte and, for an evaluation, a sample (2-byte little-endian length
// and its bytes).
#include <stdlib.h>

#include "_filter_class.h"
#include "_status_trim.h"
#include "fuzz_common.h"

typedef uint32_t (*create_fn)(const void *self, const char *class_name, const char *type_name,
                              const void *data_type, const char *expression,
                              const void *filter_parameters, void **filter_instance);
typedef uint32_t (*delete_fn)(const void *self, const char *class_name, void *filter_instance);
typedef bool (*evaluate_fn)(const void *self, const void *payload, const void *sample_info,
                            const void *reader_guid);

static bool may_create(void) { return true; }
static void created(void *filter) { (void)filter; }
static const struct cft_filter_class_owner owner = {may_create, created, CFT_STATUS_CLASS,
                                                    &cft_status_grammar};

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  struct fuzz_in in = {data, size};
  char *class_name = fuzz_string(&in, NULL);
  char *expression = fuzz_string(&in, NULL);
  char *update = fuzz_string(&in, NULL);
  const void *factory = cft_filter_factory_for(class_name, &owner);
  void *filter = NULL;
  if (factory != NULL) {
    const void *const *vtable = *(const void *const *const *)factory;
    create_fn create = (create_fn)vtable[0];
    delete_fn delete = (delete_fn)vtable[1];
    (void)cft_filter_class_compiles(class_name, expression);
    if (create(factory, class_name, "type", NULL, expression, NULL, &filter) != 0) filter = NULL;
    struct fuzz_change change;
    _Alignas(16) uint8_t sample_info[64] = {0};
    static const uint8_t reader[16] = {1, 0x0e, [15] = 0x04};
    while (filter != NULL && in.left > 0) {
      uint8_t op = fuzz_byte(&in);
      uint8_t writer[16] = {1, 0x0f};
      writer[12] = fuzz_byte(&in);
      writer[15] = op & 0x10 ? 0xc2 : 0x03;  // a built-in writer's kind, or a user writer's
      if ((op & 3) == 0) {
        size_t length;
        uint8_t *sample = fuzz_sample(&in, &length);
        fuzz_change(&change, 0, writer, 1, sample, (uint32_t)length);
        memset(sample_info, 0, sizeof sample_info);
        if (op & 0x20) memcpy(sample_info + FSI_WRITER_GUID, writer, 16);  // the sample's identity
        if (op & 0x40) sample_info[FSI_WRITER_GUID] ^= 1;                    // another writer's
        evaluate_fn evaluate = (evaluate_fn)(*(const void *const *const *)filter)[0];
        (void)evaluate(filter, change.bytes + CC_PAYLOAD, sample_info, reader);
        free(sample);
      } else if ((op & 3) == 1) {  // an update in place; a refused one keeps the filter
        (void)create(factory, class_name, "type", NULL, op & 0x80 ? update : expression, NULL,
                     &filter);
      } else if ((op & 3) == 2) {  // a filter at a writer of this process
        cft_filter_at_writer(filter, writer);
        (void)cft_filter_class_closed(writer);
      } else {
        (void)create(factory, class_name, "type", NULL, NULL, NULL, &filter);
      }
    }
    if (filter != NULL) delete(factory, class_name, filter);
  }
  free(update);
  free(expression);
  free(class_name);
  return 0;
}
