// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's DDS-SQL accelerator (_guard_filter.c), as _guard.c calls it.
#ifndef CFT_ACTION_GUARD_FILTER_H_
#define CFT_ACTION_GUARD_FILTER_H_

#include <stdbool.h>
#include <stdint.h>

#ifndef CFT_EXPORT
#define CFT_EXPORT __attribute__((visibility("default")))
#endif

// The writer whose perform_create_new_change this thread is inside, with that writer's stripe
// held; NULL elsewhere. Only then may a filter verdict use the writer's reader table.
extern __thread const void *cft_filtering_writer;

// Fast DDS 2.14 calls, made by _guard.c with the writer's stripe held, after the real member ran.
void cft_filter_reader_changed(const void *writer, const void *reader_guid, const void *reader_info);
// The reader went away, or changed while the stripe could not be held: its verdicts go to Fast DDS.
void cft_filter_reader_dropped(const void *writer, const void *reader_guid);

// Set by _guard.c once it resolved the real DDSFilterExpression::evaluate of the known Fast DDS.
typedef bool (*cft_evaluate_fn)(const void *self, const void *payload, const void *sample_info,
                                const void *reader_guid);
void cft_filter_enable(cft_evaluate_fn real_evaluate);
// The verdict for one sample and one reader: the uuid program's when there is one for the
// filtering writer and this reader, else real_evaluate's.
bool cft_filter_evaluate(const void *self, const void *payload, const void *sample_info,
                         const void *reader_guid);

#endif  // CFT_ACTION_GUARD_FILTER_H_
