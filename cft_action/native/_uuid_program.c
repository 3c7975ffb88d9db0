// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The uuid program: see _uuid_program.h for the grammar.
#include <stdlib.h>
#include <string.h>

#include "_cdr.h"
#include "_uuid_program.h"

// ---- the verdict ---------------------------------------------------------------------------------
bool cft_uuid_matches(const struct program *p, const uint8_t *uuid) {
  uint64_t u0, u1;
  memcpy(&u0, uuid, 8);
  memcpy(&u1, uuid + 8, 8);
  for (int i = 0; i < p->count; i++) {
    uint64_t m0, m1, v0, v1;
    memcpy(&m0, p->clauses[i].mask, 8);
    memcpy(&m1, p->clauses[i].mask + 8, 8);
    memcpy(&v0, p->clauses[i].value, 8);
    memcpy(&v1, p->clauses[i].value + 8, 8);
    if ((u0 & m0) == v0 && (u1 & m1) == v1) return true;
  }
  return false;
}

// ---- the parser ----------------------------------------------------------------------------------
struct parser {
  const char *at;
  const char *const *params;
  int param_count;
};

static void skip_space(struct parser *ps) {
  while (*ps->at == ' ' || *ps->at == '\t' || *ps->at == '\n' || *ps->at == '\r') ps->at++;
}

static bool is_word_char(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
         c == '.';
}

// A decimal 0..255 without a leading zero (Fast DDS reads 010 as octal), ending at a non-word
// character. Advances *s past it.
static bool byte_literal(const char **s, int *out) {
  const char *p = *s;
  if (*p < '0' || *p > '9') return false;
  if (*p == '0' && p[1] >= '0' && p[1] <= '9') return false;
  int v = 0;
  while (*p >= '0' && *p <= '9') {
    v = v * 10 + (*p - '0');
    if (v > 255) return false;
    p++;
  }
  if (is_word_char(*p)) return false;  // 1.5, 1e3, 12abc, 0x1f
  *out = v;
  *s = p;
  return true;
}

static bool keyword(struct parser *ps, const char *word) {
  size_t n = strlen(word);
  if (strncmp(ps->at, word, n) != 0 || is_word_char(ps->at[n])) return false;
  ps->at += n;
  return true;
}

// `goal_id.uuid[I]`; sets *index.
static bool uuid_field(struct parser *ps, int *index) {
  static const char field[] = "goal_id.uuid[";
  if (strncmp(ps->at, field, sizeof field - 1) != 0) return false;
  const char *p = ps->at + sizeof field - 1;
  int i;
  if (!byte_literal(&p, &i) || *p != ']' || i > 15) return false;
  ps->at = p + 1;
  *index = i;
  return true;
}

// One term, ANDed into *c; sets *never when the clause became a contradiction.
static bool term(struct parser *ps, struct clause *c, bool *never) {
  int index, value;
  skip_space(ps);
  if (!uuid_field(ps, &index)) return false;
  skip_space(ps);
  if (*ps->at != '=' || ps->at[1] == '=') return false;
  ps->at++;
  skip_space(ps);
  int other;
  if (uuid_field(ps, &other)) {
    return other == index;  // a field equals itself: no constraint; two fields: not handled here
  }
  if (*ps->at == '%') {
    const char *p = ps->at + 1;
    int n;
    if (!byte_literal(&p, &n) || n >= ps->param_count) return false;  // %0..%99 are below 256
    const char *param = ps->params[n];
    if (!byte_literal(&param, &value) || *param != '\0') return false;
    ps->at = p;
  } else if (!byte_literal(&ps->at, &value)) {
    return false;
  }
  if (c->mask[index] != 0 && c->value[index] != (uint8_t)value) *never = true;
  c->mask[index] = 0xff;
  c->value[index] = (uint8_t)value;
  return true;
}

// An atom: a term, or a parenthesized conjunction of terms. ANDs into *c.
static bool atom(struct parser *ps, struct clause *c, bool *never) {
  skip_space(ps);
  if (*ps->at != '(') return term(ps, c, never);
  ps->at++;
  if (!term(ps, c, never)) return false;
  for (;;) {
    skip_space(ps);
    if (*ps->at == ')') { ps->at++; return true; }
    if (!keyword(ps, "AND")) return false;
    if (!term(ps, c, never)) return false;
  }
}

// Appends `c` to *p, growing it; false when out of memory (*p is then still valid).
static bool append_clause(struct program **p, int *capacity, const struct clause *c) {
  if ((*p)->count == *capacity) {
    struct program *grown = realloc(*p, sizeof **p + (size_t)(*capacity * 2) * sizeof c[0]);
    if (grown == NULL) return false;
    *p = grown;
    *capacity *= 2;
  }
  (*p)->clauses[(*p)->count++] = *c;
  return true;
}

struct program *cft_uuid_compile(const char *expression, const char *const *params,
                                 int param_count) {
  struct parser ps = {expression, params, param_count};
  int capacity = 8;
  struct program *p = calloc(1, sizeof *p + (size_t)capacity * sizeof p->clauses[0]);
  if (p == NULL) return NULL;
  struct clause current;
  memset(&current, 0, sizeof current);
  bool never = false;
  enum { NONE, ALL_AND, ALL_OR } connective = NONE;
  if (!atom(&ps, &current, &never)) goto unsupported;
  for (;;) {
    skip_space(&ps);
    if (*ps.at == '\0') break;
    if (connective != ALL_OR && keyword(&ps, "AND")) {
      connective = ALL_AND;
      if (!atom(&ps, &current, &never)) goto unsupported;
      continue;
    }
    if (connective != ALL_AND && keyword(&ps, "OR")) {
      connective = ALL_OR;
      if (!never && !append_clause(&p, &capacity, &current)) goto unsupported;
      memset(&current, 0, sizeof current);
      never = false;
      if (!atom(&ps, &current, &never)) goto unsupported;
      continue;
    }
    goto unsupported;  // another token, or a second kind of connective on this level
  }
  if (!never && !append_clause(&p, &capacity, &current)) goto unsupported;
  return p;
unsupported:
  free(p);
  return NULL;
}

// Exported for the grammar test: 1 if `expression` compiles and `uuid` matches, 0 if it compiles
// and does not, -1 if it is not compiled (Fast DDS would be asked).
CFT_EXPORT int cft_uuid_filter_try(const char *expression, const char *const *params,
                                    int param_count, const uint8_t *uuid) {
  struct program *p = cft_uuid_compile(expression, params, param_count);
  if (p == NULL) return -1;
  int verdict = cft_uuid_matches(p, uuid);
  free(p);
  return verdict;
}


const uint8_t *cft_feedback_uuid(const void *payload) {
  uint32_t length;
  bool little;
  const uint8_t *body = cft_cdr_body(payload, &length, &little);
  // The uint8[16] that opens the body has no padding, and octets are the same in either byte
  // order.
  return body != NULL && length >= 16 ? body : NULL;
}
