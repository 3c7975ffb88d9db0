// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The library's own content filter classes, each answered from a few bytes of each sample:
// - CFT_ACTION_UUID, for action feedback: the goal_id.uuid grammar of _uuid_program.h, on the 16
//   uuid bytes;
// - CFT_ACTION_NODE, for /parameter_events: the node-name grammar of _node_program.h, on the
//   event's node string;
// - CFT_ACTION_RATE, for any topic: a rate limit and a poll count per writer (_rate_program.h),
//   which reads no byte of the sample: its verdict has state, decided once per sample where the
//   filter runs. The guard does not keep its readers itself (cft_filter_class_grammar): Fast DDS
//   evaluates it once per sample and reader when the sample is written, and its verdict travels in
//   the sample's filter signature, so that the reader does not decide again.
//
// Fast DDS 2.14 builds a writer-side filter for a reader only when the writer's participant has a
// factory for the reader's filter class (ReaderFilterCollection::update_entry asks
// DomainParticipantImpl::find_content_filter_factory, and keeps no entry when it returns null). A
// writer that does not know these classes therefore sends such a reader every sample, keeps no
// filter for it, puts no filter signature into its samples and has nothing for Fast-DDS#4878 to
// race on: it works exactly as with a plain rclpy reader. The reader then drops the samples it does
// not want itself, in its own process. A writer in a process run under the guard knows the
// classes, and filters on its side.
//
// The factories are found by interposing find_content_filter_factory: by preload in the guard, by
// a PLT slot in the client's process (_reader_class.c).
#ifndef CFT_ACTION_FILTER_CLASS_H_
#define CFT_ACTION_FILTER_CLASS_H_

#include <stdbool.h>
#include <stdint.h>

#define CFT_UUID_CLASS "CFT_ACTION_UUID"
#define CFT_NODE_CLASS "CFT_ACTION_NODE"
#define CFT_RATE_CLASS "CFT_ACTION_RATE"
// An action client's status reader's: answered by native/reader/_status_trim.c in the client's
// process, and by native/guard/_guard_status.c in a guarded server's, each its own way.
#define CFT_STATUS_CLASS "CFT_ACTION_STATUS"

// What a writer that filters for these classes (a writer of a guarded process) adds to its
// USER_DATA, after rmw's "typehash=...;" (a key=value; pair, which rmw's parser skips): the
// discovery data tells a reader's process which writers filter for it, since their samples carry
// no filter signature for these classes (_writer_marks.c reads it).
#define CFT_WRITER_MARK "cft_action=filters;"
// What the library's client adds to its feedback reader's USER_DATA on Fast DDS 3.3+
// (native/reader/fastdds3/): it asks a guarded server for its own goals' feedback only, which the
// guard's prefilter then sends it (native/guard/_guard_feedback.c); other readers get every sample.
#define CFT_READER_MARK "cft_action=own_feedback;"
// The same for its status reader: a guarded server sends it only the status samples that change its
// goals, or that it is owed (native/guard/_guard_status.c).
#define CFT_STATUS_READER_MARK "cft_action=own_status;"
// What a reader of any topic adds on Fast DDS 3.3+, where these classes cannot be its content
// filter: this prefix, one of the classes with a per-reader program (CFT_RATE_CLASS,
// CFT_NODE_CLASS), a space, the program's expression in that class's grammar, and ';'. A guarded
// writer then applies the program to that reader (native/guard/_guard_programs.c); the reader's
// process still applies it too, so that an unguarded writer, or one that has not read the mark
// yet, changes nothing (cft_action/topics/rate.py).
#define CFT_PROGRAM_READER_MARK "cft_action=program:"

// A class's grammar: how an expression compiles to a program (one malloc'd block, or NULL outside
// the grammar), and a program's verdict on a serialized sample (a SerializedPayload_t *). A class
// whose verdict has state gives `decide` instead of `matches`, with the sample's
// IContentFilter::FilterSampleInfo, `carry`, which moves the state of the program an update
// replaces into the new one (its filter's lock is then taken exclusively for each verdict), and
// `open`: whether a sample of the writer whose GUID is given would pass now.
struct cft_filter_grammar {
  void *(*compile)(const char *expression);
  bool (*matches)(const void *program, const void *payload);
  bool (*decide)(void *program, const void *payload, const void *sample_info);
  void (*carry)(void *program, const void *replaced);
  bool (*open)(const void *program, const uint8_t *writer_guid);
};

// What the library that links this file decides about the filters of its process: whether a
// factory may create a filter now (the guard creates them for its writers and readers; a client's
// process only for its own readers, since a writer there would filter unguarded), and what it
// does with one a factory created (not updated); `filter` is opaque. Optionally one class of its
// own (`own_class`, with `own_grammar`), which only this owner answers: the guard does not know
// it, so no writer ever filters with it. Optionally `refused`, told of every expression that a
// factory may create a filter for but that is outside its class's grammar (the filter is then not
// created, and Fast DDS keeps none). Given by that library, so that calls go one way: from it
// into this file.
struct cft_filter_class_owner {
  bool (*may_create)(void);
  void (*created)(void *filter);
  const char *own_class;
  const struct cft_filter_grammar *own_grammar;
  void (*refused)(const char *class_name, const char *type_name, const char *expression);
};

// The factory (an object with an IContentFilterFactory vtable) if `class_name` is one of these
// classes or the owner's own, else NULL. Its filters follow `owner`'s decisions from then on (the same owner on every
// call).
void *cft_filter_factory_for(const char *class_name, const struct cft_filter_class_owner *owner);

// This library's own copy of `class_name` if it names one of these classes, else NULL.
const char *cft_filter_class_name(const char *class_name);

// The grammar of `class_name` if it names one of these classes whose verdict has no state, else
// NULL: for verdicts that the guard gives without a filter instance (_guard_filter.c, "readers the
// guard keeps itself").
struct cft_filter_grammar;
const struct cft_filter_grammar *cft_filter_class_grammar(const char *class_name);
// `expression` compiled in `grammar`: one malloc'd block (free() it), or NULL outside the grammar.
void *cft_filter_grammar_compile(const struct cft_filter_grammar *grammar, const char *expression);
// The program's verdict on a SerializedPayload_t, exactly as a filter of the class gives it.
bool cft_filter_grammar_matches(const struct cft_filter_grammar *grammar, const void *program,
                                const void *payload);

// Whether `class_name` is one of these classes and compiles `expression` in this build.
bool cft_filter_class_compiles(const char *class_name, const char *expression);

// How many samples the rate class passed because their writer's GUID did not look like one (the
// layout of the headers is not the loaded library's); 0 on every stack it was tested on.
unsigned long cft_rate_layout_mismatches(void);

// A filter that a writer of this process keeps for a reader (the owner's `created`, inside the
// writer's process_reader_filter_info): `writer_guid` (16 bytes) is that writer's. Filters of a
// class with `open` are listed, until deleted, for cft_filter_class_closed.
void cft_filter_at_writer(void *filter, const uint8_t *writer_guid);
// How many of the filters listed for the writer `writer_guid` would not pass a sample of it
// written now: the matched readers that such a sample would not reach.
int cft_filter_class_closed(const uint8_t *writer_guid);

// How many verdicts `filter` has given since it was created.
unsigned long cft_filter_verdicts(const void *filter);

// How many verdicts every filter of this library has given.
unsigned long cft_filter_class_total_verdicts(void);
// How many filters of this library were created or changed.
unsigned long cft_filter_class_total_changes(void);

#endif  // CFT_ACTION_FILTER_CLASS_H_
