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

// Set by _guard.c once it resolved the real DDSFilterExpression::evaluate of the known Fast DDS;
// guard_is_relevant: the guard's DataWriterImpl::is_relevant when the real one was found too
// (readers of the library's classes may then be kept by the guard), else NULL.
typedef bool (*cft_evaluate_fn)(const void *self, const void *payload, const void *sample_info,
                                const void *reader_guid);
void cft_filter_enable(cft_evaluate_fn real_evaluate, const void *guard_is_relevant);

// Around the real process_reader_filter_info, with the writer's stripe held: begin opens a claim
// on a reader of the library's classes (true if it did); Fast DDS's find_content_filter_factory
// asks cft_filter_claimed, which is true once for the claimed class (return no factory then);
// cft_filter_reader_changed settles it; cft_filter_claim_end closes it however the call ended.
bool cft_filter_claim_begin(const void *writer, const void *reader_guid, const void *reader_info);
bool cft_filter_claimed(const char *class_name);
void cft_filter_claim_end(void);

// The topic name in a matched reader's discovery data (Fast DDS 2.14's ReaderProxyData), read
// through the layout that the verdicts use and checked as they check it (a failed check turns the
// verdicts off, as theirs does); NULL when it cannot be read.
const char *cft_filter_reader_topic(const void *reader_info, const void *reader_guid);

// A remote reader's filter of one of the library's classes whose expression is outside the class's
// grammar (no filter is created for it), and a remote reader's filter class that is named like the
// library's (CFT_ACTION in any case) but is none of them (no factory): counted, the first said once.
void cft_filter_refused(const char *class_name, const char *type_name, const char *expression);
void cft_filter_class_unknown(const char *class_name);

// DataWriterImpl::is_relevant for a reader the guard keeps: 1 or 0; -1 when Fast DDS answers.
int cft_filter_relevance(const void *writer, const void *change, const void *reader_guid);
// The verdict for one sample and one reader: the uuid program's when there is one for the
// filtering writer and this reader, else real_evaluate's.
bool cft_filter_evaluate(const void *self, const void *payload, const void *sample_info,
                         const void *reader_guid);

#endif  // CFT_ACTION_GUARD_FILTER_H_
