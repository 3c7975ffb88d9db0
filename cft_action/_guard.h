// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// What the parts of the server guard share: _guard.c (the locks, and the interposition of the
// three DataWriterImpl members), _guard_filter.c (the uuid filter verdicts) and
// _guard_writer_qos.c (the writers' limit of filtered readers).
#ifndef CFT_ACTION_GUARD_H_
#define CFT_ACTION_GUARD_H_

#include <stdbool.h>
#include <stdint.h>

#define CFT_EXPORT __attribute__((visibility("default")))

// One line on stderr, written at once so that lines of different threads do not interleave.
__attribute__((format(printf, 1, 2))) void cft_say(const char *fmt, ...);
int cft_debug_enabled(void);

// 1 when _guard.c locks the Fast DDS 2.14 it knows, whose layouts the other parts may then use.
// Decides the family's state if it is not decided yet: call it only once Fast DDS is loaded.
int cft_guard_knows_fastdds2(void);

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

#endif  // CFT_ACTION_GUARD_H_
