// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's Fast DDS 3 layer (_prefilter.cpp, built as its own library,
// _cftguard_fastdds3): what the guard's _guard_endpoints.c asks of it, after dlopen.
#ifndef CFT_ACTION_GUARD_FASTDDS3_PREFILTER_H_
#define CFT_ACTION_GUARD_FASTDDS3_PREFILTER_H_

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

// The guard's decision for a reply (_guard_replies.h, cft_reply_verdict): 0 when the reply whose
// related sample identity is `related` (16 bytes) and {high, low} must not go to `reader` (16).
typedef int (*cft_reply_verdict_fn)(const uint8_t *related, int32_t high, uint32_t low,
                                    const uint8_t *reader);

// Gives `datawriter` (an eprosima::fastdds::dds::DataWriter *, an action's response writer) a
// sample prefilter that sends each reply only to the readers `verdict` does not refuse. Returns
// DataWriter::set_sample_prefilter's ReturnCode_t (0: done).
#define CFT_FASTDDS3_ROUTE_REPLIES "cft_fastdds3_route_replies"
typedef int32_t (*cft_fastdds3_route_replies_fn)(void *datawriter, cft_reply_verdict_fn verdict);

// The guard's decision for a sample of a writer routed to marked readers (an action's feedback or
// status writer, or any writer whose readers mark a program): 0 when the sample (`data`, `length`
// bytes, encapsulation included) must not go to `reader` (16 bytes), a reader whose USER_DATA holds
// the routing's reader mark. *state is that reader's own (NULL at first), which `judge` may set;
// the layer gives it to `forget` (if not NULL) when the reader goes or loses its mark. Called with
// the routing's lock held, one at a time, as is `unjudged` (if not NULL) for each sample and reader
// passed without asking `judge` (not marked, or not known yet).
// With `update` (not NULL) the reader mark is a prefix, and the mark's value (the text after it, up
// to its ';') is the reader's program: `update` is given each new value (`length` bytes, no NUL)
// with the reader's *state, which it replaces; 0 refuses the value (the reader is then passed
// every sample, unjudged). `lookup_ms` > 0: the matched readers are looked up at most that often
// (a reader not known yet passes).
struct cft_marked_verdict {
  int (*judge)(void **state, const uint8_t *data, uint32_t length, const uint8_t *reader);
  void (*forget)(void *state);
  void (*unjudged)(void);
  int (*update)(void **state, const char *value, uint32_t length);
  int32_t lookup_ms;
};

// Gives `datawriter` a sample prefilter that asks `verdict` for the readers whose USER_DATA holds
// `reader_mark`, and passes every other sample and reader; appends `writer_mark` to the writer's
// USER_DATA (DataWriter::set_qos), so that the readers' processes see that it filters; and, with
// *heartbeat_ms > 0, makes a reliable writer's heartbeat period at most that many ms (the same
// set_qos: reliable_writer_qos().times), leaving *heartbeat_ms 0 where it did not change it.
// Returns the routing's handle for CFT_FASTDDS3_MARKED_READERS, or NULL (*error: the ReturnCode_t
// of the step that failed; the writer then stays as it was). `verdict` must outlive the writer.
#define CFT_FASTDDS3_ROUTE_MARKED "cft_fastdds3_route_marked"
typedef void *(*cft_fastdds3_route_marked_fn)(void *datawriter,
                                              const struct cft_marked_verdict *verdict,
                                              const char *reader_mark, const char *writer_mark,
                                              int32_t *heartbeat_ms, int32_t *error);

// Brings the routing `handle`'s knowledge of which readers are marked up to date with the
// discovery data of `datawriter` (its writer): the readers matched since the last call, and every
// reader again when CFT_FASTDDS3_REREAD_MS have passed since the last full reading (a reader's
// USER_DATA can change after it matched), and, with the verdict's `update`, each marked reader again
// (its program changes with its mark); with the verdict's `lookup_ms`, not more often. To be
// called outside any Fast DDS lock and callback
// (DataWriter::get_matched_subscription_data takes the participant's discovery lock): the guard
// calls it before each write of the writer (rcl_publish). Returns the marked readers' count.
#define CFT_FASTDDS3_MARKED_READERS "cft_fastdds3_marked_readers"
#define CFT_FASTDDS3_REREAD_MS 200
typedef int32_t (*cft_fastdds3_marked_readers_fn)(void *handle, void *datawriter);

// Gives back a routing's handle (its publisher is destroyed): the writer, if it still lives, keeps
// the routing.
#define CFT_FASTDDS3_RELEASE "cft_fastdds3_release"
typedef void (*cft_fastdds3_release_fn)(void *handle);

#ifdef __cplusplus
}
#endif

#endif  // CFT_ACTION_GUARD_FASTDDS3_PREFILTER_H_
