// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The library's filter classes (see _filter_class.h): Fast DDS 2.14's IContentFilterFactory and
// IContentFilter, as C objects whose first word is a vtable. Both interfaces declare only pure
// virtual members (no virtual destructor), so under the Itanium C++ ABI their vtables are exactly:
//   IContentFilterFactory: { create_content_filter, delete_content_filter }
//   IContentFilter:        { evaluate }
// tests/test_uuid_class.py checks this against the installed headers. ReturnCode_t is a trivially
// copyable class of one uint32_t, returned in eax; references are pointers.
//
// One factory per class; a class is a grammar (struct cft_filter_grammar).
#define _GNU_SOURCE
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>


#include "_fastdds_layout.h"
#include "_filter_class.h"
#include "_node_program.h"
#include "_rate_program.h"
#include "_uuid_program.h"

#define RETCODE_OK 0u
#define RETCODE_UNSUPPORTED 2u
#define RETCODE_BAD_PARAMETER 3u
#define RETCODE_OUT_OF_RESOURCES 5u

// A sample that is not a plain CDR FeedbackMessage is passed on: the client's own UUID check,
// rclpy's, then drops it if it is foreign, as it would for a plain client.
static bool uuid_matches(const void *program, const void *payload) {
  const uint8_t *uuid = cft_feedback_uuid(payload);
  return uuid == NULL || cft_uuid_matches(program, uuid);
}

// The class takes no parameters, so a %N in the expression does not compile.
static void *uuid_compile(const char *expression) { return cft_uuid_compile(expression, NULL, 0); }

// An event whose node cannot be read is passed on: the handler's callbacks still compare names.
static bool node_matches(const void *program, const void *payload) {
  uint32_t length;
  const char *node = cft_event_node(payload, &length);
  return node == NULL || cft_node_matches(program, node, length);
}

static void *node_compile(const char *expression) { return cft_node_compile(expression); }

// The writer of a sample: Fast DDS evaluates a filter on the serializedPayload member of the
// sample's CacheChange_t (a writer's DataWriterFilteredChange in update_filter_info, a reader's
// change in ContentFilteredTopicImpl::is_relevant), whose writerGUID is the writer's GUID on both
// sides; the FilterSampleInfo's sample identity holds it too, but only where the writer sent it.
// Offsets from the headers (_fastdds_layout.h); without headers the class compiles nothing, and a
// subscription that asks for it is filtered in Python instead. A GUID whose entity kind is not a
// user writer's, or that disagrees with a sample identity that is set, is a layout that is not
// the loaded library's: the sample is passed, as to a plain reader, and counted.
static unsigned long rate_layout_mismatches;

static void *rate_compile(const char *expression) {
  return CFT_LAYOUT_KNOWN ? cft_rate_compile(expression) : NULL;
}

static bool rate_decide(void *program, const void *payload, const void *sample_info) {
#if CFT_LAYOUT_KNOWN
  static const uint8_t unknown[16];
  const uint8_t *writer = (const uint8_t *)payload - CC_PAYLOAD + CC_WRITER_GUID;
  const uint8_t *identity = (const uint8_t *)sample_info + FSI_WRITER_GUID;
  uint8_t kind = writer[15];
  if ((kind != 0x02 && kind != 0x03) ||
      (memcmp(identity, unknown, 16) != 0 && memcmp(identity, writer, 16) != 0)) {
    __atomic_fetch_add(&rate_layout_mismatches, 1, __ATOMIC_RELAXED);
    return true;
  }
  return cft_rate_decide(program, writer, cft_rate_now_ns());
#else
  (void)program, (void)payload, (void)sample_info;
  return true;
#endif
}

unsigned long cft_rate_layout_mismatches(void) {
  return __atomic_load_n(&rate_layout_mismatches, __ATOMIC_RELAXED);
}

static void rate_carry(void *program, const void *replaced) { cft_rate_carry(program, replaced); }

static bool rate_open(const void *program, const uint8_t *writer_guid) {
  return cft_rate_open(program, writer_guid, cft_rate_now_ns());
}

static const struct cft_filter_grammar uuid_grammar = {uuid_compile, uuid_matches, NULL, NULL};
static const struct cft_filter_grammar node_grammar = {node_compile, node_matches, NULL, NULL};
static const struct cft_filter_grammar rate_grammar = {rate_compile, NULL, rate_decide,
                                                       rate_carry, rate_open};

// Of every filter of this library: verdicts, and filters created or changed (each is a filter
// event at a writer or a reader of this process).
static unsigned long total_verdicts, total_changes;
// Set by cft_filter_factory_for before any create.
static const struct cft_filter_class_owner *owner;

struct filter {
  const void *const *vtable;
  const struct cft_filter_grammar *grammar;
  pthread_rwlock_t lock;  // the program may be replaced while a receive thread evaluates
  void *program;
  unsigned long verdicts;
  // A filter at a writer of this process, of a class with `open` (cft_filter_at_writer): the
  // writer's GUID, in the list of writer_filters.
  bool listed;
  uint8_t writer[16];
  struct filter *prev, *next;
};

static pthread_mutex_t writer_filters_lock = PTHREAD_MUTEX_INITIALIZER;
static struct filter *writer_filters;

static bool filter_evaluate(const struct filter *self, const void *payload,
                            const void *sample_info, const void *reader_guid) {
  (void)reader_guid;
  struct filter *filter = (struct filter *)self;
  __atomic_fetch_add(&filter->verdicts, 1, __ATOMIC_RELAXED);
  __atomic_fetch_add(&total_verdicts, 1, __ATOMIC_RELAXED);
  const struct cft_filter_grammar *grammar = filter->grammar;
  if (grammar->decide != NULL) pthread_rwlock_wrlock(&filter->lock);
  else pthread_rwlock_rdlock(&filter->lock);
  bool match = grammar->decide != NULL ? grammar->decide(filter->program, payload, sample_info)
                                       : grammar->matches(filter->program, payload);
  pthread_rwlock_unlock(&filter->lock);
  return match;
}

static const void *const filter_vtable[] = {(const void *)filter_evaluate};

struct factory {
  const void *const *vtable;
  const struct cft_filter_grammar *grammar;
};

// filter_parameters is not read: these classes take no parameters.
static uint32_t factory_create(const struct factory *self, const char *class_name,
                               const char *type_name, const void *data_type,
                               const char *expression, const void *filter_parameters,
                               void **filter_instance) {
  (void)data_type, (void)filter_parameters;
  struct filter *existing = *filter_instance;
  if (expression == NULL) return existing != NULL ? RETCODE_OK : RETCODE_BAD_PARAMETER;
  const struct cft_filter_class_owner *decides = __atomic_load_n(&owner, __ATOMIC_ACQUIRE);
  if (existing == NULL && (decides == NULL || !decides->may_create())) return RETCODE_UNSUPPORTED;
  void *program = self->grammar->compile(expression);
  if (program == NULL) {
    if (decides != NULL && decides->refused != NULL)
      decides->refused(class_name, type_name, expression);
    return RETCODE_BAD_PARAMETER;
  }
  if (existing != NULL) {  // an update in place: Fast DDS hands back only this factory's filters
    pthread_rwlock_wrlock(&existing->lock);
    void *old = existing->program;
    if (self->grammar->carry != NULL) self->grammar->carry(program, old);
    existing->program = program;
    pthread_rwlock_unlock(&existing->lock);
    free(old);
    __atomic_fetch_add(&total_changes, 1, __ATOMIC_RELAXED);
    return RETCODE_OK;
  }
  struct filter *filter = calloc(1, sizeof *filter);
  if (filter == NULL) {
    free(program);
    return RETCODE_OUT_OF_RESOURCES;
  }
  filter->vtable = filter_vtable;
  filter->grammar = self->grammar;
  pthread_rwlock_init(&filter->lock, NULL);
  filter->program = program;
  *filter_instance = filter;
  __atomic_fetch_add(&total_changes, 1, __ATOMIC_RELAXED);
  decides->created(filter);
  return RETCODE_OK;
}

static uint32_t factory_delete(const struct factory *self, const char *class_name,
                               void *filter_instance) {
  (void)self, (void)class_name;
  struct filter *filter = filter_instance;
  if (filter == NULL) return RETCODE_BAD_PARAMETER;
  pthread_mutex_lock(&writer_filters_lock);
  if (filter->listed) {
    if (filter->prev != NULL) filter->prev->next = filter->next;
    else writer_filters = filter->next;
    if (filter->next != NULL) filter->next->prev = filter->prev;
  }
  pthread_mutex_unlock(&writer_filters_lock);
  pthread_rwlock_destroy(&filter->lock);
  free(filter->program);
  free(filter);
  return RETCODE_OK;
}

static const void *const factory_vtable[] = {(const void *)factory_create,
                                            (const void *)factory_delete};
static const struct factory uuid_factory = {factory_vtable, &uuid_grammar};
static const struct factory node_factory = {factory_vtable, &node_grammar};
static const struct factory rate_factory = {factory_vtable, &rate_grammar};
static struct factory own_factory = {factory_vtable, NULL};  // the owner's own class

static const struct {
  const char *name;
  const struct factory *factory;
} classes[] = {{CFT_UUID_CLASS, &uuid_factory},
               {CFT_NODE_CLASS, &node_factory},
               {CFT_RATE_CLASS, &rate_factory}};

static int class_index(const char *class_name) {
  for (int i = 0; class_name != NULL && i < (int)(sizeof classes / sizeof classes[0]); i++)
    if (strcmp(class_name, classes[i].name) == 0) return i;
  return -1;
}

const char *cft_filter_class_name(const char *class_name) {
  int i = class_index(class_name);
  return i < 0 ? NULL : classes[i].name;
}

void *cft_filter_factory_for(const char *class_name, const struct cft_filter_class_owner *by) {
  int i = class_index(class_name);
  bool own = i < 0 && class_name != NULL && by->own_class != NULL &&
             strcmp(class_name, by->own_class) == 0;
  if (i < 0 && !own) return NULL;
  __atomic_store_n(&owner, by, __ATOMIC_RELEASE);
  if (!own) return (void *)classes[i].factory;
  __atomic_store_n(&own_factory.grammar, by->own_grammar, __ATOMIC_RELEASE);
  return &own_factory;
}

const struct cft_filter_grammar *cft_filter_class_grammar(const char *class_name) {
  int i = class_index(class_name);
  return i < 0 || classes[i].factory->grammar->decide != NULL ? NULL : classes[i].factory->grammar;
}

void *cft_filter_grammar_compile(const struct cft_filter_grammar *grammar, const char *expression) {
  return grammar->compile(expression);
}

bool cft_filter_grammar_matches(const struct cft_filter_grammar *grammar, const void *program,
                                const void *payload) {
  return grammar->matches(program, payload);
}

bool cft_filter_class_compiles(const char *class_name, const char *expression) {
  int i = class_index(class_name);
  void *program =
      i < 0 || expression == NULL ? NULL : classes[i].factory->grammar->compile(expression);
  free(program);
  return program != NULL;
}

void cft_filter_at_writer(void *instance, const uint8_t *writer_guid) {
  struct filter *filter = instance;
  if (filter->grammar->open == NULL) return;
  pthread_mutex_lock(&writer_filters_lock);
  if (!filter->listed) {
    memcpy(filter->writer, writer_guid, 16);
    filter->listed = true;
    filter->prev = NULL;
    filter->next = writer_filters;
    if (writer_filters != NULL) writer_filters->prev = filter;
    writer_filters = filter;
  }
  pthread_mutex_unlock(&writer_filters_lock);
}

int cft_filter_class_closed(const uint8_t *writer_guid) {
  int closed = 0;
  pthread_mutex_lock(&writer_filters_lock);
  for (struct filter *filter = writer_filters; filter != NULL; filter = filter->next) {
    if (memcmp(filter->writer, writer_guid, 16) != 0) continue;
    pthread_rwlock_rdlock(&filter->lock);
    closed += !filter->grammar->open(filter->program, writer_guid);
    pthread_rwlock_unlock(&filter->lock);
  }
  pthread_mutex_unlock(&writer_filters_lock);
  return closed;
}

unsigned long cft_filter_verdicts(const void *filter) {
  return __atomic_load_n(&((const struct filter *)filter)->verdicts, __ATOMIC_RELAXED);
}

unsigned long cft_filter_class_total_verdicts(void) {
  return __atomic_load_n(&total_verdicts, __ATOMIC_RELAXED);
}

unsigned long cft_filter_class_total_changes(void) {
  return __atomic_load_n(&total_changes, __ATOMIC_RELAXED);
}
