// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The library's own content filter class for action feedback, CFT_ACTION_UUID: the goal_id.uuid
// grammar of _uuid_program.h, answered from the 16 uuid bytes of each sample.
//
// Fast DDS 2.14 builds a writer-side filter for a reader only when the writer's participant has a
// factory for the reader's filter class (ReaderFilterCollection::update_entry asks
// DomainParticipantImpl::find_content_filter_factory, and keeps no entry when it returns null). A
// server that does not know this class therefore sends such a reader every sample, keeps no
// filter for it, puts no filter signature into its samples and has nothing for Fast-DDS#4878 to
// race on: it works exactly as with a plain rclpy client. The reader then drops the foreign
// samples itself, in its own process, reading only 16 bytes of each. A server run under the guard
// knows the class, and filters on its side.
//
// The factory is found by interposing find_content_filter_factory: by preload in the guard, by a
// PLT slot in the client's process (_reader_class.c).
#ifndef CFT_ACTION_UUID_CLASS_H_
#define CFT_ACTION_UUID_CLASS_H_

#include <stdbool.h>

#define CFT_UUID_CLASS "CFT_ACTION_UUID"

// What the library that links this file decides about the filters of its process: whether the
// factory may create a filter now (the guard creates them for its writers and readers; a client's
// process only for its own readers, since a writer there would filter unguarded), and what it
// does with one the factory created (not updated); `filter` is opaque. Given by that library, so
// that calls go one way: from it into this file.
struct cft_uuid_class_owner {
  bool (*may_create)(void);
  void (*created)(void *filter);
};

// The factory (an object with an IContentFilterFactory vtable) if `class_name` is this class, else
// NULL. Its filters follow `owner`'s decisions from then on (the same owner on every call).
void *cft_uuid_factory_for(const char *class_name, const struct cft_uuid_class_owner *owner);

// How many verdicts `filter` has given since it was created.
unsigned long cft_uuid_filter_verdicts(const void *filter);

// How many verdicts every filter of this library has given.
unsigned long cft_uuid_class_total_verdicts(void);
// How many filters of this library were created or changed.
unsigned long cft_uuid_class_total_changes(void);

#endif  // CFT_ACTION_UUID_CLASS_H_
