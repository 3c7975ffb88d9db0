// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The node-name program: see _node_program.h for the grammar.
#include <stdlib.h>
#include <string.h>

#include "_cdr.h"
#include "_node_program.h"

#define CFT_EXPORT __attribute__((visibility("default")))

struct name {
  uint32_t offset, length;  // into the program's text
};

// One block: the names, then their text. A handler watches a few nodes, and events are rare, so
// the verdict scans them in order.
struct node_program {
  bool every;
  uint32_t count;
  struct name names[];
};

static const char *text_of(const struct node_program *p) {
  return (const char *)&p->names[p->count];
}

bool cft_node_matches(const struct node_program *p, const char *node, uint32_t length) {
  if (p->every) return true;
  const char *text = text_of(p);
  for (uint32_t i = 0; i < p->count; i++)
    if (p->names[i].length == length && memcmp(text + p->names[i].offset, node, length) == 0)
      return true;
  return false;
}

// ---- the parser ----------------------------------------------------------------------------------
static const char *skip_space(const char *s) {
  while (*s == ' ' || *s == '\t' || *s == '\n' || *s == '\r') s++;
  return s;
}

// Matches `text` (its spaces standing for any run of at least one, or none around '=' and '<>')
// at s; returns where it ends, or NULL.
static const char *expect(const char *s, const char *text) {
  for (; *text != '\0'; text++) {
    if (*text == ' ') {
      s = skip_space(s);
      continue;
    }
    if (*s != *text) return NULL;
    s++;
  }
  return s;
}

// `node = 'NAME'` at s: the name's start and length; returns where the term ends, or NULL.
static const char *term(const char *s, const char **name, uint32_t *length) {
  s = expect(s, " node = ");
  if (s == NULL || (*s != '\'' && *s != '`')) return NULL;
  const char *end = strchr(s + 1, '\'');
  if (end == NULL || memchr(s + 1, '`', (size_t)(end - s - 1)) != NULL) return NULL;
  *name = s + 1;
  *length = (uint32_t)(end - s - 1);
  return end + 1;
}

static bool at_end(const char *s) { return *skip_space(s) == '\0'; }

static bool is_or(const char *s, const char **after) {
  const char *t = skip_space(s);
  if (t == s || strncmp(t, "OR", 2) != 0 || (t[2] != ' ' && t[2] != '\t')) return false;
  *after = t + 2;
  return true;
}

struct node_program *cft_node_compile(const char *expression) {
  if (expression == NULL) return NULL;
  const char *s = expect(expression, " node = node");
  if (s != NULL && at_end(s)) {
    struct node_program *p = calloc(1, sizeof *p);
    if (p != NULL) p->every = true;
    return p;
  }
  if (s != NULL) {
    s = expect(s, " AND node <> node");
    return s != NULL && at_end(s) ? calloc(1, sizeof(struct node_program)) : NULL;
  }
  // Two passes: count and check, then copy.
  uint32_t count = 0;
  size_t text = 0;
  const char *name;
  uint32_t length;
  for (s = expression;;) {
    s = term(s, &name, &length);
    if (s == NULL) return NULL;
    count++;
    text += length;
    if (at_end(s)) break;
    if (!is_or(s, &s)) return NULL;
  }
  struct node_program *p = malloc(sizeof *p + count * sizeof(struct name) + text);
  if (p == NULL) return NULL;
  p->every = false;
  p->count = count;
  char *out = (char *)text_of(p);
  uint32_t offset = 0;
  s = expression;
  for (uint32_t i = 0; i < count; i++) {
    s = term(s, &name, &length);
    memcpy(out + offset, name, length);
    p->names[i] = (struct name){offset, length};
    offset += length;
    is_or(s, &s);
  }
  return p;
}

// ---- the sample ----------------------------------------------------------------------------------
// The node name in the body of a serialized event (`body`, `body_length` bytes, in its byte order).
static const char *node_in(const uint8_t *body, uint32_t body_length, bool little,
                           uint32_t *length) {
  if (body == NULL || body_length < 12) return NULL;
  const uint8_t *b = body + 8;  // after stamp.sec and stamp.nanosec: the string's length, with NUL
  uint32_t n = little ? (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 |
                            (uint32_t)b[3] << 24
                      : (uint32_t)b[3] | (uint32_t)b[2] << 8 | (uint32_t)b[1] << 16 |
                            (uint32_t)b[0] << 24;
  if (n == 0 || n > body_length - 12 || body[12 + n - 1] != '\0') return NULL;
  *length = n - 1;
  return (const char *)body + 12;
}

const char *cft_event_node(const void *payload, uint32_t *length) {
  uint32_t body_length = 0;
  bool little = false;
  const uint8_t *body = cft_cdr_body(payload, &body_length, &little);
  return node_in(body, body_length, little, length);
}

const char *cft_event_node_bytes(const uint8_t *data, uint32_t size, uint32_t *length) {
  uint32_t body_length = 0;
  bool little = false;
  const uint8_t *body = cft_cdr_bytes(data, size, &body_length, &little);
  return node_in(body, body_length, little, length);
}

// Exported for the grammar test: 1 if `expression` compiles and the event `payload` (a
// SerializedPayload_t *) passes it, 0 if it compiles and the event does not, -1 if it is not in
// the grammar, -2 if the event's node cannot be read.
CFT_EXPORT int cft_node_filter_try(const char *expression, const void *payload) {
  uint32_t length;
  const char *node = cft_event_node(payload, &length);
  if (node == NULL) return -2;
  struct node_program *p = cft_node_compile(expression);
  if (p == NULL) return -1;
  int verdict = cft_node_matches(p, node, length);
  free(p);
  return verdict;
}
