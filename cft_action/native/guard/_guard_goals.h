// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// Whose goal is it (_guard_goals.c): the participant that requested each goal the server took, as
// the status filter (_guard_status.c) and the feedback verdict (_guard_feedback.c) ask it, in a
// process of either Fast DDS family.
#ifndef CFT_ACTION_GUARD_GOALS_H_
#define CFT_ACTION_GUARD_GOALS_H_

#include <stdint.h>

#ifndef CFT_EXPORT
#define CFT_EXPORT __attribute__((visibility("default")))
#endif

#define CFT_UUID_SIZE 16
#define CFT_PREFIX_SIZE 12

// What the record says of the goal `uuid` (16 bytes) for the reader `reader_guid` (16 bytes; its
// first 12, the GUID prefix, name its participant).
enum cft_goal_owner {
  CFT_GOAL_UNKNOWN,  // no request for it was recorded (or the record was cleared since)
  CFT_GOAL_READERS,  // the reader's participant requested it
  CFT_GOAL_OTHERS,   // another participant requested it
};
enum cft_goal_owner cft_goal_owner(const uint8_t *uuid, const uint8_t *reader_guid);

// Records that the participant of the writer `guid` (16 bytes) requested the goal `uuid`, unless
// another participant did first (counted and said once: CFT_GOALS_CONTESTED). rmw_take_request
// records each goal request so; the fuzz harness of the status verdict too.
void cft_goals_record(const uint8_t *uuid, const uint8_t *guid);

// Forgets every request (as when the record is full).
void cft_goals_clear(void);

// A hash of a goal UUID's 16 bytes, for the open-addressing tables of goals.
uint64_t cft_uuid_mix(const uint8_t *uuid);

// The record's counters: goal requests recorded, request headers that did not name a user
// endpoint, times the full record was cleared, requests for a goal another participant had
// requested (in this order, from 0).
enum { CFT_GOALS_REQUESTS, CFT_GOALS_IMPLAUSIBLE, CFT_GOALS_RESETS, CFT_GOALS_CONTESTED,
       CFT_GOALS_COUNTERS };
unsigned long cft_goals_count(int which);

#endif  // CFT_ACTION_GUARD_GOALS_H_
