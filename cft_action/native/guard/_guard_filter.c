// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The server guard's filter verdicts: what a writer-side goal_id.uuid filter costs the server.
//
// Fast DDS 2.14 evaluates a writer-side DDS-SQL filter in DDSFilterExpression::evaluate by
// deserializing the whole sample into a DynamicData, once per filtered reader and sample, so a
// server with 16 filtered clients and 1 kB feedback publishes some 30 times slower than with plain
// clients (docs/BENCHMARKS.md, "The server's cost"). A filter whose every term is
// `goal_id.uuid[i] = <0..255>` has a verdict that depends only on the 16 bytes after the 4-byte
// CDR encapsulation of an action FeedbackMessage, whose first member is goal_id. This file answers
// such filters from those bytes, and leaves every other filter to Fast DDS.
//
// Where the expression comes from. Fast DDS builds a writer's filter for a reader only in
// DataWriterImpl::process_reader_filter_info, from the ContentFilterProperty of the reader's
// discovery data, and drops it only there (an unusable update) or in remove_reader_filter. Both are
// interposed by _guard.c, which calls this file after the real member ran, with the writer's stripe
// held. Whatever Fast DDS did then, a later evaluate for that (writer, reader) uses a filter built
// from exactly that property (ReaderFilterCollection::update_entry keeps a filter only when the MD5
// signature of class, topic, expression and parameters is unchanged), or is not called at all
// (no filter: removed, over the writer's filter limit, data-sharing, multicast). So the program
// compiled here from the same property gives the same verdicts.
//
// Soundness rules:
// - Only an expression in the grammar of _uuid_program.h is compiled; anything else goes to Fast DDS.
// - Only for a reader of an action feedback topic (`rt/.../_action/feedback`) whose type is an
//   action FeedbackMessage (`<pkg>::action::dds_::<Name>_FeedbackMessage_`), with filter class
//   DDSSQL, and a sample in plain CDR (encapsulation 0x0000 or 0x0001) of at least 20 bytes.
// - Only inside perform_create_new_change of the writer whose table entry it is, with that writer's
//   stripe held (cft_filtering_writer), so table changes and verdicts of one writer never overlap.
// - An entry remembers the filter instance of its first verdict; any other instance for it means
//   a change this file did not see, and the entry is dropped.
// - The ReaderProxyData layout comes from the Fast DDS headers the guard was built against
//   (_fastdds_layout.h), checked on the loaded library's own data before it is used (see "reading
//   the reader's discovery data" below); every string read through it is checked for a sane length
//   and terminator, and one failed check turns the verdicts off for the process, said once.
// - CFT_GUARD_VERIFY=1 asks Fast DDS too for every compiled verdict, counts disagreements and
//   returns Fast DDS's verdict; CFT_GUARD_ACCELERATE=0 turns this file off.

#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "_fastdds_layout.h"
#include "_guard_filter.h"
#include "_filter_class.h"
#include "_guard_log.h"
#include "_guard_status.h"
#include "_guard_text.h"
#include "_uuid_program.h"

__thread const void *cft_filtering_writer;

// ---- Fast DDS layouts, from the headers the guard was built against (_fastdds_layout.h) ----------
#define MAX_PARAMETERS 100
#define MAX_EXPRESSION 65536        // an RTPS parameter cannot carry more
// How far from the headers' m_guid the reader's GUID is looked for in the loaded library's
// ReaderProxyData (apt's SECURITY=ON build: 8 bytes later).
#define SHIFT_WINDOW 64
// SecurityManager::cancel_init(), exported only by a Fast DDS built with SECURITY=ON.
#define SECURITY_ONLY_SYMBOL "_ZN8eprosima8fastrtps4rtps8security15SecurityManager11cancel_initEv"

// Exported for the layout tests: {which} -> the headers' offset the guard reads at; -1 past the end
// (and for every `which` in a build without headers). The order is tests/test_guard_filter.py's.
CFT_EXPORT long cft_guard_filter_layout(int which) {
#if CFT_LAYOUT_KNOWN
  static const long layout[] = {RPD_TYPE_NAME, RPD_CONTENT_FILTER, CFP_RELATED_TOPIC,
                                CFP_CLASS_NAME, CFP_EXPRESSION, CFP_PARAMETERS, RLV_VECTOR,
                                STRING255_SIZE, STRING255_LENGTH, PAYLOAD_LENGTH, PAYLOAD_DATA,
                                RPD_GUID, RPD_KEY, RPD_TOPIC_NAME, CC_KIND, CC_KIND_SIZE,
                                CC_PAYLOAD, PAYLOAD_MAX_SIZE, CC_WRITER_GUID,
                                CC_RELATED_WRITER_GUID, CC_RELATED_SEQUENCE, FSI_WRITER_GUID};
  return which >= 0 && which < (int)(sizeof layout / sizeof layout[0]) ? layout[which] : -1;
#else
  (void)which;
  return -1;
#endif
}

// Exported for the layout tests: the include path of the headers the layout came from ("" without).
CFT_EXPORT const char *cft_guard_layout_includes(void) { return CFT_LAYOUT_INCLUDES; }

// ---- counters (cft_guard_filter_count) -----------------------------------------------------------
enum {
  C_FAST,          // verdicts given from the uuid bytes
  C_REAL,          // verdicts left to Fast DDS's evaluate
  C_COMPILED,      // reader filters compiled to a uuid program
  C_NOT_COMPILED,  // reader filters left to Fast DDS (not uuid-only, or not a feedback reader)
  C_DROPPED,       // entries dropped: reader removed, or a change seen without the stripe
  C_EVICTED,       // entries evicted from a full table (their verdicts go back to Fast DDS)
  C_FOREIGN,       // entries dropped because a verdict came for another filter instance
  C_VERIFIED,      // verdicts compared with Fast DDS's (CFT_GUARD_VERIFY=1)
  C_MISMATCH,      // of those, disagreements (always 0, or this file is wrong)
  C_KEPT,          // readers of the library's classes kept in the table instead of Fast DDS's
  C_LEFT,          // readers of those classes left to Fast DDS (see cft_filter_claim_begin)
  C_RELEVANCE,     // verdicts given in is_relevant for the readers kept
  C_REFUSED,       // remote readers' filters of the library's classes outside their grammar
  C_UNKNOWN,       // remote readers' filter classes named like the library's, none of them
  C_COUNT
};
static unsigned long counters[C_COUNT];
static void count(int which) { __atomic_fetch_add(&counters[which], 1, __ATOMIC_RELAXED); }

CFT_EXPORT unsigned long cft_guard_filter_count(int which) {
  return which >= 0 && which < C_COUNT ? __atomic_load_n(&counters[which], __ATOMIC_RELAXED) : 0;
}

// ---- reading the reader's discovery data -----------------------------------------------------------
// The headers give the layout of the Fast DDS the guard was built against; the library loaded may
// be another build of 2.14 (apt's is SECURITY=ON, which puts two masks before m_guid and so moves
// every later field). So the layout is checked against the loaded library's own data before it is
// used: Fast DDS passes the reader's GUID beside its ReaderProxyData, and the data holds that GUID
// twice, in m_guid and in m_key. The first reader's data is searched for the GUID within
// SHIFT_WINDOW bytes of the headers' m_guid, where m_key holds it too at the same distance; the
// headers' layout from m_guid on, moved by that distance (`shift`), is then the layout. Every
// reader's data is checked again before its filter is read: its GUID in m_guid and in m_key, sane
// type, topic and class names and expression. One failed check turns the verdicts off for the
// process. What the remote reader chose (a related topic name other than its topic name, where
// Fast DDS does not filter, or an expression holding a NUL) is not a failed check: that reader's
// verdicts are Fast DDS's.
static bool layout_failed;  // set once, read without a lock: verdicts then all go to Fast DDS
static pthread_mutex_t layout_lock = PTHREAD_MUTEX_INITIALIZER;
#if CFT_LAYOUT_KNOWN
static bool layout_located;  // set once, after shift (release)
static long shift;
#endif
static char layout_report[512] = "not checked yet: no filtered reader has been seen";

// HAVE_SECURITY of the loaded libfastrtps, for the report: "1" when it exports a symbol that only
// a security build has. Looked up once, in cft_filter_enable, where _guard.c has just resolved
// that library (no dlopen under a writer's stripe).
static const char *loaded_security = "?";

// Said only once a DDS-SQL filter is evaluated, when it matters: the library's own clients use
// their own filter classes (_filter_class.h), which never comes here, and a server that only has such
// clients, or none, has nothing to be told.
static void say_layout_failure(void) {
  static bool said;
  if (__atomic_load_n(&layout_failed, __ATOMIC_ACQUIRE) && !__atomic_exchange_n(&said, true, __ATOMIC_RELAXED))
    cft_say("filter verdicts off: %s; every DDS-SQL filter goes to Fast DDS", layout_report);
}

static void layout_suspect(const char *what) {
  pthread_mutex_lock(&layout_lock);
  if (!__atomic_load_n(&layout_failed, __ATOMIC_RELAXED)) {
#if CFT_LAYOUT_KNOWN
    snprintf(layout_report, sizeof layout_report,
             "the loaded Fast DDS (HAVE_SECURITY %s) does not hold its reader discovery data in the "
             "layout of %s%s (%s)", loaded_security, CFT_LAYOUT_SOURCE,
             layout_located ? ", moved to where the reader's GUID was found" : "", what);
#else
    snprintf(layout_report, sizeof layout_report,
             "the guard knows no Fast DDS layout: it was built from %s", what);
#endif
    __atomic_store_n(&layout_failed, true, __ATOMIC_RELEASE);
  }
  pthread_mutex_unlock(&layout_lock);
}

// What the guard knows about the layout it reads (for guard.layout()).
CFT_EXPORT const char *cft_guard_filter_layout_report(void) {
  pthread_mutex_lock(&layout_lock);
  static char copy[sizeof layout_report];
  memcpy(copy, layout_report, sizeof copy);
  pthread_mutex_unlock(&layout_lock);
  return copy;
}

// A reader's filter, as read from its discovery data (read_reader_filter).
struct reader_filter {
  const char *type, *related, *class_name, *expression;
  const char *params[MAX_PARAMETERS];
  int param_count;
};

#if CFT_LAYOUT_KNOWN
// A fixed_string<255>, or NULL when its length and terminator disagree.
static const char *string255(const uint8_t *at) {
  size_t length;
  memcpy(&length, at + STRING255_LENGTH, sizeof length);
  if (length >= STRING255_LENGTH || at[length] != '\0' || memchr(at, '\0', length) != NULL) return NULL;
  return (const char *)at;
}

static bool holds_guid(const uint8_t *info, long at, const uint8_t *guid) {
  return memcmp(info + at + shift, guid, 16) == 0;
}

// The distance of the loaded library's m_guid from the headers', found once; false when the
// reader's GUID is not where the headers' layout, moved as a whole, would have it.
static bool located(const uint8_t *info, const uint8_t *guid) {
  if (__atomic_load_n(&layout_located, __ATOMIC_ACQUIRE)) return true;
  pthread_mutex_lock(&layout_lock);
  int found = 0;
  long at = 0;
  for (long d = -SHIFT_WINDOW; !layout_located && d <= SHIFT_WINDOW; d += 4) {
    if (memcmp(info + RPD_GUID + d, guid, 16) == 0 && memcmp(info + RPD_KEY + d, guid, 16) == 0) {
      found++;
      at = d;
    }
  }
  if (!layout_located && found == 1 && !__atomic_load_n(&layout_failed, __ATOMIC_RELAXED)) {
    char moved[64] = "as is";
    if (at != 0) snprintf(moved, sizeof moved, "moved %ld bytes %s from m_guid on", at > 0 ? at : -at,
                          at > 0 ? "later" : "earlier");
    snprintf(layout_report, sizeof layout_report,
             "the layout of %s, %s, checked on the loaded Fast DDS (HAVE_SECURITY %s): the reader's "
             "GUID in m_guid and m_key", CFT_LAYOUT_SOURCE, moved, loaded_security);
    shift = at;
    __atomic_store_n(&layout_located, true, __ATOMIC_RELEASE);
    if (cft_debug_enabled()) cft_say("reader discovery data: %s", layout_report);
  }
  bool ok = layout_located;
  pthread_mutex_unlock(&layout_lock);
  return ok;
}

// rosidl's DDS name of an action feedback message: <pkg>::action::dds_::<Name>_FeedbackMessage_.
static bool is_feedback_type(const char *type) {
  const char *ns = strstr(type, "::action::dds_::");
  return ns != NULL && ns != type && strchr(ns + 16, ':') == NULL &&
         cft_ends_with(type, "_FeedbackMessage_");
}

// What a reader's discovery data says about its filter, read through the checked layout.
// Reads the reader's filter into *f. False when the data fails a check (the layout is then
// suspect, and every verdict goes back to Fast DDS) or the reader has no filter (*filtered false).
// True when the reader's data holds its GUID where the checked layout has it (m_guid and m_key).
static bool holds_its_guid(const uint8_t *info, const uint8_t *guid) {
  if (!located(info, guid)) {
    layout_suspect("the reader's GUID is not in m_guid and m_key, as a whole or moved");
    return false;
  }
  if (!holds_guid(info, RPD_GUID, guid) || !holds_guid(info, RPD_KEY, guid)) {
    layout_suspect("a reader's GUID is not where the first reader's was");
    return false;
  }
  return true;
}

static bool read_reader_filter(const uint8_t *info, const uint8_t *guid, struct reader_filter *f,
                               bool *filtered) {
  if (!holds_its_guid(info, guid)) return false;
  const uint8_t *cfp = info + RPD_CONTENT_FILTER + shift;
  const char *topic = string255(info + RPD_TOPIC_NAME + shift);
  f->type = string255(info + RPD_TYPE_NAME + shift);
  f->related = string255(cfp + CFP_RELATED_TOPIC);
  f->class_name = string255(cfp + CFP_CLASS_NAME);
  if (f->type == NULL || topic == NULL || f->related == NULL || f->class_name == NULL) {
    layout_suspect("a topic, type or filter class name");
    return false;
  }
  *filtered = f->class_name[0] != '\0';
  if (!*filtered) return false;
  // Fast DDS filters for a reader only when its filter's related topic is the writer's topic,
  // which the reader's topic is too (they matched). Another related topic is the remote reader's
  // choice, not a sign of the layout: the guard leaves such a reader to Fast DDS.
  if (strcmp(f->related, topic) != 0) return false;
  size_t length;
  memcpy(&f->expression, cfp + CFP_EXPRESSION, sizeof f->expression);
  memcpy(&length, cfp + CFP_EXPRESSION + sizeof f->expression, sizeof length);
  if (f->expression == NULL || length >= MAX_EXPRESSION || f->expression[length] != '\0') {
    layout_suspect("the filter expression");
    return false;
  }
  // A std::string holds what the remote reader sent, NULs too: no grammar of the guard's takes one.
  if (memchr(f->expression, '\0', length) != NULL) return false;
  const uint8_t *begin, *end;
  memcpy(&begin, cfp + CFP_PARAMETERS + RLV_VECTOR, sizeof begin);
  memcpy(&end, cfp + CFP_PARAMETERS + RLV_VECTOR + sizeof begin, sizeof end);
  if (end < begin || (size_t)(end - begin) % STRING255_SIZE != 0 ||
      (size_t)(end - begin) / STRING255_SIZE > MAX_PARAMETERS) {
    layout_suspect("the expression parameters");
    return false;
  }
  f->param_count = (int)((size_t)(end - begin) / STRING255_SIZE);
  for (int i = 0; i < f->param_count; i++) {
    f->params[i] = string255(begin + (size_t)i * STRING255_SIZE);
    if (f->params[i] == NULL) {
      layout_suspect("an expression parameter");
      return false;
    }
  }
  return true;
}

// The reader's uuid program, or NULL when it has no filter (*filtered false) or one this file
// does not answer.
static struct program *program_of(const uint8_t *info, const uint8_t *guid, bool *filtered) {
  struct reader_filter f;
  if (!read_reader_filter(info, guid, &f, filtered)) return NULL;
  struct program *program = NULL;
  if (strcmp(f.class_name, "DDSSQL") == 0 && strncmp(f.related, "rt/", 3) == 0 &&
      cft_ends_with(f.related, "/_action/feedback") && is_feedback_type(f.type))
    program = cft_uuid_compile(f.expression, f.params, f.param_count);
  if (cft_debug_enabled())
    cft_say("reader filter on %s (%s, %s): %s: %.200s", f.related, f.type, f.class_name,
            program ? "uuid verdicts" : "left to Fast DDS", f.expression);
  return program;
}
#else
// Built without Fast DDS headers: no layout to read the reader's filter with.
static bool read_reader_filter(const uint8_t *info, const uint8_t *guid, struct reader_filter *f,
                               bool *filtered) {
  (void)info, (void)guid, (void)f, (void)filtered;
  layout_suspect(CFT_LAYOUT_SOURCE);
  return false;
}
static struct program *program_of(const uint8_t *info, const uint8_t *guid, bool *filtered) {
  struct reader_filter f;
  read_reader_filter(info, guid, &f, filtered);
  return NULL;
}
#endif

const char *cft_filter_reader_topic(const void *reader_info, const void *reader_guid) {
  if (reader_info == NULL || reader_guid == NULL || __atomic_load_n(&layout_failed, __ATOMIC_RELAXED))
    return NULL;
#if CFT_LAYOUT_KNOWN
  const uint8_t *info = reader_info;
  if (!holds_its_guid(info, reader_guid)) return NULL;
  const char *topic = string255(info + RPD_TOPIC_NAME + shift);
  if (topic == NULL) layout_suspect("a topic name");
  return topic;
#else
  layout_suspect(CFT_LAYOUT_SOURCE);
  return NULL;
#endif
}

// ---- the table: (writer, reader GUID) -> program ---------------------------------------------------
// Open addressing with a bounded probe. A missing entry is always safe (Fast DDS decides), so a
// full neighbourhood evicts. Verdicts hold table_lock while they use a program, so an eviction by
// another writer never frees a program in use.
#define TABLE_SLOTS 16384
#define PROBE 16
struct entry {
  const void *writer;      // NULL: free
  uint8_t reader[16];
  const void *instance;    // the filter instance of the first verdict, NULL before it
  void *program;           // a uuid program, or a program of `kept`'s grammar
  const struct cft_filter_grammar *kept;  // non-NULL: a reader the guard keeps (see below)
};
static unsigned long kept_entries;  // entries with `kept`, for is_relevant's lock-free "none"
static struct entry table[TABLE_SLOTS];
static pthread_mutex_t table_lock = PTHREAD_MUTEX_INITIALIZER;

// splitmix64's finalizer: every input bit reaches every output bit. The readers of one writer
// differ only in a byte or two of their entity id (the last 4 of 16 GUID bytes), which a plain
// multiply-and-shift left out of the slot's low bits: 40 readers of one writer shared 2 windows.
static uint64_t mix(uint64_t x) {
  x ^= x >> 30;
  x *= 0xBF58476D1CE4E5B9ull;
  x ^= x >> 27;
  x *= 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

static unsigned slot_of(const void *writer, const uint8_t *reader) {
  uint64_t r0, r1;
  memcpy(&r0, reader, 8);
  memcpy(&r1, reader + 8, 8);
  return (unsigned)(mix((uint64_t)(uintptr_t)writer ^ mix(r0 ^ mix(r1))) % TABLE_SLOTS);
}

static struct entry *find_locked(const void *writer, const uint8_t *reader) {
  unsigned home = slot_of(writer, reader);
  for (unsigned i = 0; i < PROBE; i++) {
    struct entry *e = &table[(home + i) % TABLE_SLOTS];
    if (e->writer == writer && memcmp(e->reader, reader, 16) == 0) return e;
  }
  return NULL;
}

static void clear_locked(struct entry *e) {
  if (e->kept != NULL) __atomic_fetch_sub(&kept_entries, 1, __ATOMIC_RELAXED);
  free(e->program);
  memset(e, 0, sizeof *e);
}

// A free slot in the entry's window, or its own; NULL when every slot is another's.
static struct entry *room_locked(const void *writer, const uint8_t *reader) {
  struct entry *e = find_locked(writer, reader);
  unsigned home = slot_of(writer, reader);
  for (unsigned i = 0; i < PROBE && e == NULL; i++)
    if (table[(home + i) % TABLE_SLOTS].writer == NULL) e = &table[(home + i) % TABLE_SLOTS];
  return e;
}

// Entries are never moved, so a free slot inside a probe window does not end a search: lookups
// always look at the whole window.
// A full window evicts an entry that is not a kept reader's when it has one (a kept reader evicted
// receives every sample, with no signature, and its own reader filters them).
static void store_locked(const void *writer, const uint8_t *reader, void *program,
                         const struct cft_filter_grammar *kept) {
  struct entry *e = room_locked(writer, reader);
  if (e == NULL) {
    unsigned home = slot_of(writer, reader);
    e = &table[home];
    for (unsigned i = 0; i < PROBE; i++)
      if (table[(home + i) % TABLE_SLOTS].kept == NULL) {
        e = &table[(home + i) % TABLE_SLOTS];
        break;
      }
    count(C_EVICTED);
  }
  clear_locked(e);
  e->writer = writer;
  memcpy(e->reader, reader, 16);
  e->program = program;
  e->kept = kept;
  if (kept != NULL) __atomic_fetch_add(&kept_entries, 1, __ATOMIC_RELAXED);
}

static void drop(const void *writer, const void *reader_guid, int why) {
  if (reader_guid == NULL) return;
  pthread_mutex_lock(&table_lock);
  struct entry *e = find_locked(writer, reader_guid);
  if (e != NULL) {
    clear_locked(e);
    count(why);
  }
  pthread_mutex_unlock(&table_lock);
}

// ---- what the guard refused ------------------------------------------------------------------------
// A remote reader's filter comes from its discovery data, which any participant on the domain
// writes: a filter of the library's classes whose expression is outside the class's grammar is not
// created (the factory refuses it, and Fast DDS keeps no filter for the reader), and a class named
// like the library's but none of them has no factory. Either way the writer sends that reader
// every sample, as to a plain reader. Each is counted; the first of each kind is said, once.

static const char *printable(char *out, size_t size, const char *text, size_t limit) {
  return cft_printable(out, size, text, strlen(text), limit);
}

void cft_filter_refused(const char *class_name, const char *type_name, const char *expression) {
  count(C_REFUSED);
  static bool said;
  if (!cft_first(&said)) return;
  char type[256], text[256];
  cft_say("refused a remote reader's %s filter for the type %s: its expression (%zu bytes: \"%s\") "
          "is not in that class's grammar, so its writers keep no filter for it and send it every "
          "sample, as to a plain reader (said once; cft_action.guard.filter_counts()['refused'] "
          "counts each)", class_name, printable(type, sizeof type, type_name ? type_name : "?", 60),
          expression ? strlen(expression) : 0,
          printable(text, sizeof text, expression ? expression : "", 40));
}

void cft_filter_class_unknown(const char *class_name) {
  if (class_name == NULL || strcasestr(class_name, "CFT_ACTION") == NULL ||
      strcmp(class_name, CFT_STATUS_CLASS) == 0 || cft_filter_class_name(class_name) != NULL)
    return;
  count(C_UNKNOWN);
  static bool said;
  if (!cft_first(&said)) return;
  char name[256];
  cft_say("a remote reader's filter class \"%s\" is none of the library's (%s, %s, %s, %s): its "
          "writers keep no filter for it and send it every sample, as to a plain reader (said "
          "once; cft_action.guard.filter_counts()['unknown_classes'] counts each)",
          printable(name, sizeof name, class_name, 60), CFT_UUID_CLASS, CFT_NODE_CLASS,
          CFT_RATE_CLASS, CFT_STATUS_CLASS);
}

// ---- the hooks -------------------------------------------------------------------------------------
static cft_evaluate_fn real_evaluate;  // set once, before the family turns active
static bool enabled, verify;
static const void *relevance_slot;     // the guard's is_relevant, or NULL: no reader is kept
static bool keep_readers;              // CFT_GUARD_KEEP_READERS is not 0

void cft_filter_enable(cft_evaluate_fn real, const void *guard_is_relevant) {
  void *handle = dlopen("libfastrtps.so.2.14", RTLD_LAZY | RTLD_NOLOAD);
  if (handle != NULL) {
    loaded_security = dlsym(handle, SECURITY_ONLY_SYMBOL) != NULL ? "1" : "0";
    dlclose(handle);
  }
  const char *off = getenv("CFT_GUARD_ACCELERATE");
  const char *check = getenv("CFT_GUARD_VERIFY");
  const char *keep = getenv("CFT_GUARD_KEEP_READERS");
  real_evaluate = real;
  verify = check != NULL && check[0] != '\0' && strcmp(check, "0") != 0;
  enabled = !(off != NULL && strcmp(off, "0") == 0);
  relevance_slot = guard_is_relevant;
  keep_readers = guard_is_relevant != NULL && CFT_LAYOUT_KNOWN && !(keep != NULL && strcmp(keep, "0") == 0);
  if (cft_debug_enabled())
    cft_say("uuid filter verdicts %s%s; readers of the library's classes %s",
            enabled ? "on" : "off (CFT_GUARD_ACCELERATE=0)",
            verify ? ", each checked against Fast DDS (CFT_GUARD_VERIFY)" : "",
            keep_readers ? "kept by the guard" : "left to Fast DDS");
}

// ---- readers the guard keeps itself ----------------------------------------------------------------
// Fast DDS 2.14 writes PID_CONTENT_FILTER_INFO, 16 bytes of signature per reader of its writer's
// ReaderFilterCollection, into every DATA that writer sends, to every reader. A reader whose filter
// is of one of the library's classes (_filter_class.h) judges a sample from a few bytes, so the
// signature saves it nothing; it is kept out of the collection instead, and the guard answers for
// it where the RTPS writer asks whether a change is relevant for a reader:
// DataWriterImpl::is_relevant, IReaderDataFilter's one member, which ReaderProxy::rtps_is_relevant
// (reliable writers: once per change and reader, when the change is added or a late joiner
// matched) and StatelessWriter (best effort: at each send) call through the writer's vtable.
//
// How a reader gets here. _guard.c calls cft_filter_claim_begin before the real
// process_reader_filter_info, with the writer's stripe held. If the reader's filter is of a
// library class and compiles, the claim is open on this thread. Fast DDS then checks what it
// always checks (the writer filters at all, the reader is not reached by data-sharing and has no
// multicast locator, its filter's related topic is the writer's, the collection has room) and
// only then asks find_content_filter_factory for the class: there _guard.c asks
// cft_filter_claimed, which answers true once, and returns no factory, so that Fast DDS keeps no
// entry for the reader (and drops one it had). After the real member, cft_filter_reader_changed
// stores the program as a kept entry if Fast DDS asked, and drops the reader's entry otherwise. So
// exactly the readers Fast DDS would have filtered for are filtered for, by the same program as the
// class's filter instance would have run (cft_filter_grammar_matches), without their signature.
//
// The verdict is given when the RTPS writer asks, not when the sample is written: for a reliable
// writer that is in the same write, with the stripe held, so the filter is the one Fast DDS would
// have used; a best-effort writer asks at each send and gets the filter of that moment.
//
// A writer is kept only if its vtable's first slot (IReaderDataFilter's is_relevant, the primary
// base's member: DataWriterImpl derives from it first) is the guard's definition, i.e. the virtual
// call lands here; otherwise, and if the table has no room, Fast DDS keeps the reader as before.
struct claim {
  bool open, asked;
  const void *writer;
  uint8_t reader[16];
  const struct cft_filter_grammar *grammar;
  void *program;
};
static __thread struct claim claim;

// The grammar of a class whose readers the guard keeps: the stateless library classes', and the
// status class's (_guard_status.c); NULL for any other.
static const struct cft_filter_grammar *claim_grammar(const char *class_name) {
  if (class_name != NULL && strcmp(class_name, CFT_STATUS_CLASS) == 0)
    return &cft_guard_status_grammar;
  return cft_filter_class_grammar(class_name);
}

static void say_once(bool *said, const char *what) {
  if (cft_first(said)) cft_say("%s", what);
}

bool cft_filter_claim_begin(const void *writer, const void *reader_guid, const void *reader_info) {
  if (!keep_readers || reader_guid == NULL || reader_info == NULL ||
      __atomic_load_n(&layout_failed, __ATOMIC_RELAXED))
    return false;
  const void *const *vtable = *(const void *const *const *)writer;
  if (vtable[0] != relevance_slot) {
    static bool said;
    say_once(&said, "a writer whose vtable does not call the guard's is_relevant: its readers of "
                    "the library's filter classes keep Fast DDS's filter signatures");
    count(C_LEFT);
    return false;
  }
  struct reader_filter f;
  bool filtered = false;
  if (!read_reader_filter(reader_info, reader_guid, &f, &filtered)) return false;
  const struct cft_filter_grammar *grammar = claim_grammar(f.class_name);
  if (grammar == NULL) return false;
  // The status class, only for an action's status reader (_guard_status.c).
  if (grammar == &cft_guard_status_grammar && !cft_status_keeps(f.related, f.type)) return false;
  // An expression outside the class's grammar: its factory refuses it too, and Fast DDS keeps no
  // filter for the reader, which then receives every sample.
  void *program = cft_filter_grammar_compile(grammar, f.expression);
  if (program == NULL) {
    // The factories of the other classes refuse it too (and say so); the status class has none.
    if (grammar == &cft_guard_status_grammar) cft_filter_refused(f.class_name, f.type, f.expression);
    return false;
  }
  pthread_mutex_lock(&table_lock);
  bool room = room_locked(writer, reader_guid) != NULL;
  pthread_mutex_unlock(&table_lock);
  if (!room) {
    free(program);
    count(C_LEFT);
    return false;
  }
  claim = (struct claim){true, false, writer, {0}, grammar, program};
  memcpy(claim.reader, reader_guid, 16);
  return true;
}

bool cft_filter_claimed(const char *class_name) {
  if (!claim.open || claim.asked || claim_grammar(class_name) != claim.grammar) return false;
  claim.asked = true;
  return true;
}

void cft_filter_claim_end(void) {
  free(claim.program);  // still here unless cft_filter_reader_changed stored it
  memset(&claim, 0, sizeof claim);
}

// Ends an open claim for this reader: true when it was this reader's.
static bool settle_claim(const void *writer, const void *reader_guid) {
  if (!claim.open || claim.writer != writer || memcmp(claim.reader, reader_guid, 16) != 0)
    return false;
  pthread_mutex_lock(&table_lock);
  if (claim.asked) {
    store_locked(writer, reader_guid, claim.program, claim.grammar);
    claim.program = NULL;
    if (claim.grammar == &cft_guard_status_grammar) cft_status_reader_kept();
  } else {
    struct entry *e = find_locked(writer, reader_guid);
    if (e != NULL) clear_locked(e);
  }
  pthread_mutex_unlock(&table_lock);
  count(claim.asked ? C_KEPT : C_DROPPED);
  if (cft_debug_enabled())
    cft_say("reader of a library filter class %s", claim.asked ? "kept by the guard" :
            "not filtered by this writer (Fast DDS would not filter for it)");
  claim.open = false;
  return true;
}

void cft_filter_reader_changed(const void *writer, const void *reader_guid, const void *reader_info) {
  if (reader_guid == NULL || settle_claim(writer, reader_guid)) return;
  if (!enabled) {
    drop(writer, reader_guid, C_DROPPED);  // a kept reader whose filter left the classes
    return;
  }
  bool filtered = reader_info != NULL;
  struct program *program = reader_info != NULL && !__atomic_load_n(&layout_failed, __ATOMIC_RELAXED)
                                ? program_of(reader_info, reader_guid, &filtered) : NULL;
  if (program == NULL) {
    if (filtered) count(C_NOT_COMPILED);
    drop(writer, reader_guid, C_DROPPED);
    return;
  }
  count(C_COMPILED);
  pthread_mutex_lock(&table_lock);
  store_locked(writer, reader_guid, program, NULL);
  pthread_mutex_unlock(&table_lock);
}

void cft_filter_reader_dropped(const void *writer, const void *reader_guid) {
  drop(writer, reader_guid, C_DROPPED);
}

// The kept reader's verdict on a change: 1 or 0, or -1 when the reader is not kept for this writer
// (Fast DDS's own is_relevant answers then) or the change is not ALIVE (always relevant, as in
// ReaderFilterCollection::update_filter_info).
int cft_filter_relevance(const void *writer, const void *change, const void *reader_guid) {
  if (__atomic_load_n(&kept_entries, __ATOMIC_RELAXED) == 0 || reader_guid == NULL ||
      __atomic_load_n(&layout_failed, __ATOMIC_RELAXED))
    return -1;
#if CFT_LAYOUT_KNOWN
  const uint8_t *c = change;
  uint32_t kind, length, max_size;
  const void *data;
  _Static_assert(CC_KIND_SIZE == sizeof kind, "ChangeKind_t is not 4 bytes");
  memcpy(&kind, c + CC_KIND, sizeof kind);
  memcpy(&length, c + CC_PAYLOAD + PAYLOAD_LENGTH, sizeof length);
  memcpy(&data, c + CC_PAYLOAD + PAYLOAD_DATA, sizeof data);
  memcpy(&max_size, c + CC_PAYLOAD + PAYLOAD_MAX_SIZE, sizeof max_size);
  // ChangeKind_t has 4 values, ALIVE first; a payload fits its buffer.
  if (kind > 3 || length > max_size || (length > 0 && data == NULL)) {
    layout_suspect("a change whose kind or payload is not where the headers have them");
    return -1;
  }
  if (kind != 0) return -1;
  int verdict = -1;
  pthread_mutex_lock(&table_lock);
  struct entry *e = find_locked(writer, reader_guid);
  if (e != NULL && e->kept == &cft_guard_status_grammar)
    verdict = cft_status_verdict(&e->program, c + CC_PAYLOAD, reader_guid);
  else if (e != NULL && e->kept != NULL)
    verdict = cft_filter_grammar_matches(e->kept, e->program, c + CC_PAYLOAD);
  pthread_mutex_unlock(&table_lock);
  if (verdict >= 0) count(C_RELEVANCE);
  return verdict;
#else
  (void)writer, (void)change;
  return -1;
#endif
}

// 1 or 0 from the uuid program, -1 when there is none for this verdict.
static int uuid_verdict(const void *self, const void *payload, const void *reader_guid) {
  const void *writer = cft_filtering_writer;
  if (writer == NULL || reader_guid == NULL || __atomic_load_n(&layout_failed, __ATOMIC_RELAXED))
    return -1;
  const uint8_t *uuid = cft_feedback_uuid(payload);
  if (uuid == NULL) return -1;
  int verdict = -1;
  pthread_mutex_lock(&table_lock);
  struct entry *e = find_locked(writer, reader_guid);
  if (e != NULL && e->kept == NULL) {
    if (e->instance == NULL) e->instance = self;
    if (e->instance == self) {
      verdict = cft_uuid_matches(e->program, uuid);
    } else {
      clear_locked(e);
      count(C_FOREIGN);
    }
  }
  pthread_mutex_unlock(&table_lock);
  return verdict;
}

bool cft_filter_evaluate(const void *self, const void *payload, const void *sample_info,
                         const void *reader_guid) {
  int verdict = enabled ? uuid_verdict(self, payload, reader_guid) : -1;
  if (verdict < 0) {
    say_layout_failure();
    count(C_REAL);
    return real_evaluate(self, payload, sample_info, reader_guid);
  }
  if (verify) {
    bool theirs = real_evaluate(self, payload, sample_info, reader_guid);
    count(C_VERIFIED);
    if (theirs != (verdict == 1)) {
      count(C_MISMATCH);
      cft_say("uuid filter verdict %d disagrees with Fast DDS's %d", verdict, (int)theirs);
      return theirs;
    }
  }
  count(C_FAST);
  return verdict == 1;
}
