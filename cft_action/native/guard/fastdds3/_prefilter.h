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

#ifdef __cplusplus
}
#endif

#endif  // CFT_ACTION_GUARD_FASTDDS3_PREFILTER_H_
