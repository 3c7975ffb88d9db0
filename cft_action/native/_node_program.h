// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// A /parameter_events filter by node name, for the CFT_ACTION_NODE class (_filter_class.h). Its
// expressions are the DDS-SQL that cft_action.parameters.parameter_events writes, with the names inline:
//     expr  := node = node                          every event
//            | node = node AND node <> node         no event
//            | term ( OR term )*
//     term  := node = 'NAME'    (or `NAME', the other opening quote DDS-SQL knows)
// NAME has no quote; names compare byte for byte with the event's node, as DDS-SQL's = does.
#ifndef CFT_ACTION_NODE_PROGRAM_H_
#define CFT_ACTION_NODE_PROGRAM_H_

#include <stdbool.h>
#include <stdint.h>

struct node_program;

// The program of `expression` (free() it), or NULL outside the grammar (or out of memory).
struct node_program *cft_node_compile(const char *expression);
bool cft_node_matches(const struct node_program *p, const char *node, uint32_t length);

// The node name of a serialized rcl_interfaces/msg/ParameterEvent (a SerializedPayload_t *) and
// its length without the terminator, or NULL when the sample is not plain CDR or too short for
// its own string. The body opens with builtin_interfaces/Time (int32, uint32), then the string.
const char *cft_event_node(const void *payload, uint32_t *length);
// The same for the event's serialized bytes (`size` of them, encapsulation included), as Fast DDS
// 3's public API hands them over.
const char *cft_event_node_bytes(const uint8_t *data, uint32_t size, uint32_t *length);

#endif  // CFT_ACTION_NODE_PROGRAM_H_
