// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// An action client's status samples, trimmed to its own goals before Python sees them.
//
// An action server's GoalStatusArray lists every goal it holds, and goes to every client at every
// transition of any goal; rclpy converts the whole array to Python and then looks each entry's
// UUID up among its own goal handles. Here the serialized sample (plain CDR, as rcl's
// rcl_take_serialized_message gives it) is read natively, and a new GoalStatusArray is written
// with only the entries that can change one of this client's goal handles:
//
// - a goal whose goal handle exists ("accepted"): an entry whose status differs from the last one
//   delivered, and the first after acceptance. rclpy's update of a handle is idempotent (it sets
//   the status, and forgets the handle at a terminal one), so an unchanged entry changes nothing.
//   After a terminal entry the goal is forgotten here too;
// - a goal whose request was sent and whose response has not been executed ("pending"): only
//   when its response was taken with the sample, since rclpy's execute then makes the goal handle
//   before it reads the status. rclpy takes one goal response per wake, so that is one goal; when
//   the caller cannot tell which, every pending goal's entry goes. The status of the last sample
//   that listed a pending goal is kept: cft_status_table_responded() returns it when the goal is
//   accepted, so that the new handle gets it. A status that came before the response updates no
//   handle in rclpy, and the server may send none later that lists the goal with it (a guarded
//   server sends a client only samples that change its goals; any server, none once the client's
//   goals and every other goal are done).
//
// Goals are added by cft_status_table_sending() before their request is written, and moved from
// pending by cft_status_table_responded(). A mutex serializes them with cft_status_trim(), since
// goals may be sent from any thread while the executor takes status.
//
// The status reader itself drops, in its receive thread, a sample that can change none of the
// client's goal handles, so that it never wakes the executor: the filter class CFT_STATUS_CLASS
// (_status_trim.h), whose expression names the table by a number (never an address: the
// expression travels to the server by discovery). A sample passes if it lists a pending goal, or
// an accepted goal with another status than in the last sample that passed. The reader evaluates
// every sample in order, and its keep-last 1 history is replaced only by samples that pass, so it
// always holds (or has handed to the executor) a sample with the latest status of every one of
// the client's goals, as a plain reader's history would. A goal is in the table before the server
// can list it (its request is sent after cft_status_table_sending).
//
// The CDR (classic, XCDR1, as rmw_fastrtps writes it): a 4-byte encapsulation header (0x00 0x00
// big endian, 0x00 0x01 little endian, then two option bytes), then, aligned from the body's
// start: uint32 count; per GoalStatus: uint8 uuid[16], int32 sec and uint32 nanosec
// (builtin_interfaces/Time, 4-byte aligned), int8 status. The first entry takes 25 bytes, every
// later one 28 (3 bytes of padding before sec).
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "_cdr.h"
#include "_status_trim.h"

#define EXPORT __attribute__((visibility("default")))

#define UUID_SIZE 16
#define PENDING 0
#define ACCEPTED 1
#define UNDELIVERED (-1)  // `last` of an accepted goal before its first delivery

// action_msgs/GoalStatus: STATUS_SUCCEEDED, STATUS_CANCELED, STATUS_ABORTED.
static bool is_terminal(int8_t status) { return status == 4 || status == 5 || status == 6; }

struct slot {
  uint8_t uuid[UUID_SIZE];
  bool used;
  uint8_t state;  // PENDING or ACCEPTED
  int16_t last;   // accepted: the status last delivered, or UNDELIVERED
  int16_t seen;   // accepted: the status in the last sample the reader's filter passed, or UNDELIVERED
  int16_t early;  // pending: the status in the last sample that listed it, or UNDELIVERED
};

struct cft_status_table {
  pthread_mutex_t lock;
  struct slot *slots;
  size_t capacity;  // a power of two
  size_t count;
  unsigned long samples, entries, delivered;
};

static size_t hash(const uint8_t *uuid) {
  // client mode's UUIDs share their first bytes (the client's tag): mix all sixteen.
  uint64_t a, b;
  memcpy(&a, uuid, 8);
  memcpy(&b, uuid + 8, 8);
  uint64_t h = (a ^ (b * 0x9E3779B97F4A7C15ull)) * 0xBF58476D1CE4E5B9ull;
  return (size_t)(h ^ (h >> 31));
}

static struct slot *find(struct cft_status_table *t, const uint8_t *uuid) {
  size_t mask = t->capacity - 1;
  for (size_t i = hash(uuid) & mask;; i = (i + 1) & mask) {
    struct slot *s = &t->slots[i];
    if (!s->used) return NULL;
    if (memcmp(s->uuid, uuid, UUID_SIZE) == 0) return s;
  }
}

static struct slot *place(struct slot *slots, size_t capacity, const uint8_t *uuid) {
  size_t mask = capacity - 1;
  size_t i = hash(uuid) & mask;
  while (slots[i].used && memcmp(slots[i].uuid, uuid, UUID_SIZE) != 0) i = (i + 1) & mask;
  return &slots[i];
}

static int grow(struct cft_status_table *t) {
  size_t capacity = t->capacity * 2;
  struct slot *slots = calloc(capacity, sizeof *slots);
  if (slots == NULL) return -1;
  for (size_t i = 0; i < t->capacity; i++)
    if (t->slots[i].used) *place(slots, capacity, t->slots[i].uuid) = t->slots[i];
  free(t->slots);
  t->slots = slots;
  t->capacity = capacity;
  return 0;
}

// Linear probing's deletion: shift later members of the run back into the hole.
static void erase(struct cft_status_table *t, struct slot *s) {
  size_t mask = t->capacity - 1;
  size_t hole = (size_t)(s - t->slots);
  for (size_t i = (hole + 1) & mask; t->slots[i].used; i = (i + 1) & mask) {
    size_t home = hash(t->slots[i].uuid) & mask;
    // Move slot i into the hole unless its home lies cyclically in (hole, i].
    bool stays = hole <= i ? (hole < home && home <= i) : (hole < home || home <= i);
    if (!stays) {
      t->slots[hole] = t->slots[i];
      hole = i;
    }
  }
  t->slots[hole].used = false;
  t->count--;
}

// The tables by number (index + 1), for the reader filters; a number is never reused, and a freed
// table leaves NULL, so that a filter that outlives its table passes every sample.
static pthread_mutex_t registry_lock = PTHREAD_MUTEX_INITIALIZER;
static struct cft_status_table **registry;
static size_t registry_size, registry_capacity;

EXPORT struct cft_status_table *cft_status_table_new(void) {
  struct cft_status_table *t = calloc(1, sizeof *t);
  if (t == NULL) return NULL;
  t->capacity = 64;
  t->slots = calloc(t->capacity, sizeof *t->slots);
  if (t->slots == NULL) {
    free(t);
    return NULL;
  }
  pthread_mutex_init(&t->lock, NULL);
  pthread_mutex_lock(&registry_lock);
  if (registry_size == registry_capacity) {
    size_t capacity = registry_capacity ? 2 * registry_capacity : 16;
    struct cft_status_table **grown = realloc(registry, capacity * sizeof *grown);
    if (grown != NULL) registry = grown, registry_capacity = capacity;
  }
  if (registry_size < registry_capacity) registry[registry_size++] = t;
  pthread_mutex_unlock(&registry_lock);
  return t;
}

// The table's number for the filter expression `cft_status_table = <number>`; 0 if it has none.
EXPORT unsigned long cft_status_table_number(const struct cft_status_table *t) {
  unsigned long number = 0;
  pthread_mutex_lock(&registry_lock);
  for (size_t i = 0; i < registry_size && number == 0; i++)
    if (registry[i] == t) number = i + 1;
  pthread_mutex_unlock(&registry_lock);
  return number;
}

EXPORT void cft_status_table_free(struct cft_status_table *t) {
  if (t == NULL) return;
  pthread_mutex_lock(&registry_lock);
  for (size_t i = 0; i < registry_size; i++)
    if (registry[i] == t) registry[i] = NULL;
  pthread_mutex_unlock(&registry_lock);
  pthread_mutex_destroy(&t->lock);
  free(t->slots);
  free(t);
}

// A goal's request is about to be written: its entries are delivered from now on. 0, or -1 when
// out of memory.
EXPORT int cft_status_table_sending(struct cft_status_table *t, const uint8_t *uuid) {
  int ret = 0;
  pthread_mutex_lock(&t->lock);
  if ((t->count + 1) * 2 > t->capacity && grow(t) != 0) {
    ret = -1;
  } else {
    struct slot *s = place(t->slots, t->capacity, uuid);
    if (!s->used) t->count++;
    memcpy(s->uuid, uuid, UUID_SIZE);
    s->used = true;
    s->state = PENDING;
    s->last = s->seen = s->early = UNDELIVERED;
  }
  pthread_mutex_unlock(&t->lock);
  return ret;
}

// The goal's response was executed: accepted (its goal handle exists now), or not (forgotten).
EXPORT int cft_status_table_responded(struct cft_status_table *t, const uint8_t *uuid,
                                      int accepted) {
  int early = UNDELIVERED;
  pthread_mutex_lock(&t->lock);
  struct slot *s = find(t, uuid);
  if (s != NULL && s->state == PENDING) {
    if (accepted) {
      early = s->early;
      s->state = ACCEPTED;
      // The early status goes to the new handle now: later entries pass when they differ from it.
      s->last = s->seen = (int16_t)early;
      if (early != UNDELIVERED && is_terminal((int8_t)early)) erase(t, s);
    } else {
      erase(t, s);
    }
  }
  pthread_mutex_unlock(&t->lock);
  return early;
}

static uint32_t read_u32(const uint8_t *p, bool little) {
  return little ? (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24
                : (uint32_t)p[3] | (uint32_t)p[2] << 8 | (uint32_t)p[1] << 16 | (uint32_t)p[0] << 24;
}

static void write_u32(uint8_t *p, uint32_t v, bool little) {
  for (int i = 0; i < 4; i++) p[little ? i : 3 - i] = (uint8_t)(v >> (8 * i));
}

static size_t align4(size_t offset) { return (offset + 3) & ~(size_t)3; }

// The body offset of the entry after the one at `pos`, and the status of the one at `pos`.
static size_t next_entry(size_t pos) { return align4(pos + UUID_SIZE) + 9; }
static int8_t status_at(const uint8_t *body, size_t pos) {
  return (int8_t)body[align4(pos + UUID_SIZE) + 8];
}

// Whether the entry (uuid, status) goes to Python; updates the goal's record.
static bool deliver(struct cft_status_table *t, const uint8_t *uuid, int8_t status,
                    const uint8_t *responding, bool all_pending) {
  struct slot *s = find(t, uuid);
  if (s == NULL) return false;
  if (s->state == PENDING) {
    s->early = status;
    return all_pending || (responding != NULL && memcmp(responding, uuid, UUID_SIZE) == 0);
  }
  if (s->last == status) return false;
  s->last = status;
  if (is_terminal(status)) erase(t, s);
  return true;
}

// Read the GoalStatusArray `in` (`in_length` bytes, with its encapsulation header) and write into
// `out` (at least `in_length` bytes) a GoalStatusArray of the same encoding with only the entries
// that deliver() selects, in their order; *out_length: its bytes. `responding`: the UUID of the
// goal whose response was taken with the sample, or NULL; `all_pending`: a response was taken but
// its goal is not known. Returns the entries written, or -1 if `in` is not a plain CDR
// GoalStatusArray (then nothing was changed, and the caller converts the whole sample, as rclpy
// does).
EXPORT long cft_status_trim(struct cft_status_table *t, const uint8_t *in, size_t in_length,
                            uint8_t *out, size_t *out_length, const uint8_t *responding,
                            int all_pending) {
  if (in_length < 8 || in[0] != 0 || in[1] > 1) return -1;
  bool little = in[1] == 1;
  const uint8_t *body = in + 4;
  size_t length = in_length - 4;
  uint32_t count = read_u32(body, little);
  // Check the whole sample before changing any record.
  size_t end = 4;
  for (uint32_t i = 0; i < count; i++) {
    end = align4(end + UUID_SIZE) + 9;
    if (end > length) return -1;
  }
  uint8_t *out_body = out + 4;
  size_t at = 4;
  long written = 0;
  pthread_mutex_lock(&t->lock);
  t->samples++;
  t->entries += count;
  size_t pos = 4;
  for (uint32_t i = 0; i < count; i++) {
    const uint8_t *uuid = body + pos;
    size_t stamp = align4(pos + UUID_SIZE);
    int8_t status = (int8_t)body[stamp + 8];
    pos = stamp + 9;
    if (!deliver(t, uuid, status, responding, all_pending)) continue;
    memcpy(out_body + at, uuid, UUID_SIZE);
    size_t out_stamp = align4(at + UUID_SIZE);
    memset(out_body + at + UUID_SIZE, 0, out_stamp - (at + UUID_SIZE));
    memcpy(out_body + out_stamp, body + stamp, 9);
    at = out_stamp + 9;
    written++;
  }
  t->delivered += (unsigned long)written;
  pthread_mutex_unlock(&t->lock);
  out[0] = 0;
  out[1] = in[1];
  out[2] = out[3] = 0;
  write_u32(out_body, (uint32_t)written, little);
  *out_length = 4 + at;
  return written;
}

// --- the reader's filter class --------------------------------------------------------------------

struct status_program {
  unsigned long number;
};

static void *status_compile(const char *expression) {
  unsigned long number;
  int end = 0;
  if (expression == NULL || sscanf(expression, " cft_status_table = %lu %n", &number, &end) != 1 ||
      expression[end] != '\0' || number == 0)
    return NULL;
  struct status_program *program = malloc(sizeof *program);
  if (program != NULL) program->number = number;
  return program;
}

// Whether the sample lists a pending goal of the table, or an accepted one whose status changed
// since the last sample that passed; if it passes, it is the last one. A sample that cannot be
// read, or whose table is gone, passes: the trim then decides, or rclpy.
static bool status_matches(const void *program, const void *payload) {
  uint32_t length;
  bool little;
  const uint8_t *body = cft_cdr_body(payload, &length, &little);
  if (body == NULL || length < 4) return true;
  uint32_t count = read_u32(body, little);
  size_t number = ((const struct status_program *)program)->number;
  bool passes = false;
  pthread_mutex_lock(&registry_lock);
  struct cft_status_table *t = number <= registry_size ? registry[number - 1] : NULL;
  size_t end = 4;
  for (uint32_t i = 0; i < count && end <= length; i++) end = next_entry(end);
  if (t == NULL || end > length) {
    passes = true;  // no table, or a malformed sample: pass it on
  } else {
    pthread_mutex_lock(&t->lock);
    // With no goal in the table (a client whose goals have all ended), nothing is looked up.
    for (size_t i = 0, pos = 4; i < count && !passes && t->count > 0; i++, pos = next_entry(pos)) {
      const struct slot *s = find(t, body + pos);
      passes = s != NULL && (s->state == PENDING || s->seen != status_at(body, pos));
    }
    if (passes) {  // the last sample that passed: record its statuses
      for (size_t i = 0, pos = 4; i < count; i++, pos = next_entry(pos)) {
        struct slot *s = find(t, body + pos);
        if (s != NULL && s->state == ACCEPTED) s->seen = status_at(body, pos);
      }
    }
    pthread_mutex_unlock(&t->lock);
  }
  pthread_mutex_unlock(&registry_lock);
  return passes;
}

const struct cft_filter_grammar cft_status_grammar = {status_compile, status_matches};

// Counters: 0 samples read, 1 entries in them, 2 entries delivered, 3 goals in the table.
EXPORT unsigned long cft_status_table_count(struct cft_status_table *t, int which) {
  pthread_mutex_lock(&t->lock);
  unsigned long value = which == 0   ? t->samples
                        : which == 1 ? t->entries
                        : which == 2 ? t->delivered
                                     : (unsigned long)t->count;
  pthread_mutex_unlock(&t->lock);
  return value;
}
