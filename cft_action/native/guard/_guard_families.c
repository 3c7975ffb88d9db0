// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The Fast DDS families the server guard knows (_guard_families.h): which one is loaded, where
// the real definitions of the members it interposes are, and whether it locks them (its state and
// the reason, for cft_action/guard.py). The real definitions are found lazily, on first use, in the
// Fast DDS library that is already loaded:
//   1. dlopen(<known soname>, RTLD_NOLOAD) + dlsym: the only case in which the guard locks;
//   2. otherwise every loaded libfastrtps.so* / libfastdds.so* (dl_iterate_phdr), then
//      dlsym(RTLD_NEXT): the guard calls straight through, without locking, and says once on
//      stderr that it is inactive and why.
// RTLD_NEXT alone does not work: rmw loads Fast DDS with RTLD_LOCAL, outside the global scope.
// Also what every part of the guard asks of it: the parts' switches and periods, and the real
// definitions of other libraries' members. It calls no other part but _guard_log.c.

#define _GNU_SOURCE
#include <dlfcn.h>
#include <link.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "_guard_families.h"
#include "_guard_log.h"
#include "_guard_text.h"

static struct family families[] = {
  {"Fast DDS 2", {"libfastrtps.so.2.14"}, "libfastrtps.so", {PCNC2, PRFI2, RRF2, EVAL2, FIND, REL2},
   {0}, 0, PTHREAD_MUTEX_INITIALIZER, ""},
  {"Fast DDS 3", {"libfastdds.so.3.6", "libfastdds.so.3.2"}, "libfastdds.so",
   {PCNC3, PRFI3, RRF3, NULL, FIND, NULL}, {0}, 0, PTHREAD_MUTEX_INITIALIZER, ""},
};
#define N_FAMILIES ((int)(sizeof(families) / sizeof(families[0])))

static int loaded_after_fastdds;         // set by the constructor
static char late_reason[512];

// ---- finding the real definitions -------------------------------------------------------------------
static const char *base_name(const char *path) {
  const char *slash = strrchr(path, '/');
  return slash ? slash + 1 : path;
}

// Loaded objects whose basename starts with a Fast DDS prefix, collected by dl_iterate_phdr.
#define MAX_FOUND 8
struct loaded_list {
  int count;
  char paths[MAX_FOUND][512];
};

static int collect_cb(struct dl_phdr_info *info, size_t size, void *data) {
  (void)size;
  struct loaded_list *list = data;
  const char *name = info->dlpi_name;
  if (name == NULL || name[0] == '\0' || list->count >= MAX_FOUND) return 0;
  const char *base = base_name(name);
  for (int i = 0; i < N_FAMILIES; i++) {
    if (strncmp(base, families[i].prefix, strlen(families[i].prefix)) == 0) {
      snprintf(list->paths[list->count++], sizeof list->paths[0], "%s", name);
      break;
    }
  }
  return 0;
}

static void loaded_fastdds(struct loaded_list *list) {
  list->count = 0;
  dl_iterate_phdr(collect_cb, list);  // dlopen is called only after it returns
}

static int family_of_path(const char *path) {
  const char *base = base_name(path);
  for (int i = 0; i < N_FAMILIES; i++)
    if (strncmp(base, families[i].prefix, strlen(families[i].prefix)) == 0) return i;
  return -1;
}

// Whether `p` is defined in the guard itself (a definition found in the global scope, which the
// guard's interposed members are in).
static bool ours(void *p) {
  Dl_info found, self;
  return p != NULL && dladdr(p, &found) && dladdr((void *)&families, &self) &&
         found.dli_fbase == self.dli_fbase;
}

// Looks up all of the family's names in `handle`. Returns how many of the locked members were
// found; the guard's own definition (which could only come from the global scope) is rejected.
static int lookup_all(struct family *f, void *handle, void *out[FN_COUNT]) {
  int found = 0;
  for (int i = 0; i < FN_COUNT; i++) {
    void *p = f->names[i] != NULL ? dlsym(handle, f->names[i]) : NULL;
    if (ours(p)) p = NULL;
    out[i] = p;
    if (i < FN_LOCKED) found += p != NULL;
  }
  return found;
}

static const char *object_of(void *addr, char *buf, size_t len) {
  Dl_info info;
  if (addr != NULL && dladdr(addr, &info) && info.dli_fname != NULL)
    snprintf(buf, len, "%s", info.dli_fname);
  else
    snprintf(buf, len, "?");
  return buf;
}

// The family's known sonames, comma-separated, in `buf`.
static const char *known_names(const struct family *f, char *buf, size_t len) {
  size_t used = 0;
  buf[0] = '\0';
  for (size_t i = 0; i < KNOWN_SONAMES && f->known_sonames[i] != NULL && used < len; i++)
    used += snprintf(buf + used, len - used, "%s%s", i ? ", " : "", f->known_sonames[i]);
  return buf;
}

// Sets the family's final state. Called with resolve_lock held and state == ARMED.
// With from_call == 0 (a probe from cft_guard_state) it leaves the state ARMED when no library of
// this family is loaded yet; from an interposed call it always decides.
static void resolve_locked(int fam, int from_call) {
  struct family *f = &families[fam];
  void *real[FN_COUNT] = {0};
  char where[512];
  int state = CFT_GUARD_INACTIVE;

  const char *known = NULL;
  void *handle = NULL;
  for (size_t i = 0; handle == NULL && i < KNOWN_SONAMES && f->known_sonames[i] != NULL; i++)
    if ((handle = dlopen(f->known_sonames[i], RTLD_LAZY | RTLD_NOLOAD)) != NULL)
      known = f->known_sonames[i];
  if (handle != NULL) {
    int found = lookup_all(f, handle, real);
    // The handle is kept on purpose: the cached pointers must not outlive the library.
    if (found == FN_LOCKED && !loaded_after_fastdds) {
      state = CFT_GUARD_ACTIVE;
      snprintf(f->reason, sizeof f->reason, "active: %s (%s)", known,
               object_of(real[FN_PCNC], where, sizeof where));
    } else if (found == FN_LOCKED) {
      snprintf(f->reason, sizeof f->reason, "inactive: %.480s", late_reason);
    } else {
      snprintf(f->reason, sizeof f->reason,
               "inactive: %s is loaded but lacks %d of the %d DataWriterImpl members this guard "
               "wraps; not locking", known, FN_LOCKED - found, FN_LOCKED);
    }
  } else {
    // Not the known version. Find the real definitions anyway, to call straight through.
    struct loaded_list list;
    loaded_fastdds(&list);
    const char *seen = NULL;
    for (int i = 0; i < list.count; i++) {
      if (family_of_path(list.paths[i]) != fam) continue;
      seen = list.paths[i];
      void *h = dlopen(list.paths[i], RTLD_LAZY | RTLD_NOLOAD);
      if (h == NULL) continue;
      void *candidate[FN_COUNT];
      if (lookup_all(f, h, candidate) > 0) {
        memcpy(real, candidate, sizeof real);
        break;  // keep h: the pointers refer into it
      }
      dlclose(h);
    }
    for (int i = 0; i < FN_COUNT; i++) {
      if (real[i] != NULL || f->names[i] == NULL) continue;
      void *p = dlsym(RTLD_NEXT, f->names[i]);
      real[i] = ours(p) ? NULL : p;
    }
    int found = (real[0] != NULL) + (real[1] != NULL) + (real[2] != NULL);
    if (found == 0 && seen == NULL && !from_call) return;  // nothing of this family loaded yet
    if (found > 0) {
      char known_list[128];
      snprintf(f->reason, sizeof f->reason,
               "inactive: %s is not a Fast DDS version this guard knows (it knows %s); calling "
               "it directly, without locking",
               object_of(real[real[0] ? 0 : real[1] ? 1 : 2], where, sizeof where),
               known_names(f, known_list, sizeof known_list));
    } else if (from_call) {
      snprintf(f->reason, sizeof f->reason,
               "inactive: cannot find the real %s DataWriterImpl members (loaded: %s); writes "
               "fail and filter changes are skipped", f->label, seen ? seen : "none");
    } else {
      snprintf(f->reason, sizeof f->reason,
               "inactive: %s does not export the DataWriterImpl members this guard wraps (not a "
               "Fast DDS version it knows); nothing is locked", seen);
    }
  }

  memcpy(f->real, real, sizeof real);
  __atomic_store_n(&f->state, state, __ATOMIC_RELEASE);
  if (state != CFT_GUARD_ACTIVE)
    cft_say("%s", f->reason);  // the one line the user needs; printed once per family
  else if (cft_debug_enabled())
    cft_say("%s", f->reason);
}

static void resolve(int fam, int from_call) {
  struct family *f = &families[fam];
  pthread_mutex_lock(&f->resolve_lock);
  if (__atomic_load_n(&f->state, __ATOMIC_ACQUIRE) == CFT_GUARD_ARMED) resolve_locked(fam, from_call);
  pthread_mutex_unlock(&f->resolve_lock);
}

struct family *cft_family_ready(int fam) {
  struct family *f = &families[fam];
  if (__builtin_expect(__atomic_load_n(&f->state, __ATOMIC_ACQUIRE) == CFT_GUARD_ARMED, 0))
    resolve(fam, 1);
  return f;
}

void *cft_guard_real(void **cache, const char *soname, const char *name) {
  void *p = __atomic_load_n(cache, __ATOMIC_ACQUIRE);
  if (p != NULL) return p;
  void *handle = dlopen(soname, RTLD_LAZY | RTLD_NOLOAD);
  p = handle != NULL ? dlsym(handle, name) : NULL;
  if (p == NULL) p = dlsym(RTLD_NEXT, name);
  __atomic_store_n(cache, p, __ATOMIC_RELEASE);
  return p;
}

void *cft_guard_real_in_caller(void **cache, const char *name, const void *return_address) {
  void *p = __atomic_load_n(cache, __ATOMIC_ACQUIRE);
  if (p != NULL) return p;
  Dl_info info;
  if (dladdr(return_address, &info) != 0 && info.dli_fname != NULL) {
    void *handle = dlopen(info.dli_fname, RTLD_LAZY | RTLD_NOLOAD);
    p = handle != NULL ? dlsym(handle, name) : NULL;
  }
  if (p == NULL) p = dlsym(RTLD_NEXT, name);
  __atomic_store_n(cache, p, __ATOMIC_RELEASE);
  return p;
}

// Every loaded object's path, collected by dl_iterate_phdr (which holds the loader's lock, so that
// dlopen comes after it).
#define MAX_OBJECTS 512
struct objects {
  int count;
  char *names[MAX_OBJECTS];
};

static int collect_object(struct dl_phdr_info *info, size_t size, void *data) {
  (void)size;
  struct objects *o = data;
  if (info->dlpi_name != NULL && info->dlpi_name[0] != '\0' && o->count < MAX_OBJECTS) {
    char *name = strdup(info->dlpi_name);
    if (name != NULL) o->names[o->count++] = name;
  }
  return 0;
}

void *cft_guard_loaded_symbol(const char *name, const char *prefer) {
  struct objects o = {0};
  dl_iterate_phdr(collect_object, &o);
  void *found = NULL;
  bool preferred = false;
  for (int i = 0; i < o.count; i++) {
    void *handle = dlopen(o.names[i], RTLD_LAZY | RTLD_NOLOAD);
    void *p = handle != NULL ? dlsym(handle, name) : NULL;
    Dl_info where;
    // Defined in this object itself, not found through its dependencies, and not the guard's.
    if (p != NULL && !ours(p) && dladdr(p, &where) != 0 && where.dli_fname != NULL &&
        strcmp(where.dli_fname, o.names[i]) == 0) {
      bool better = prefer != NULL && strstr(o.names[i], prefer) != NULL;
      if (found == NULL || (better && !preferred)) found = p, preferred = better;
    }
    // The handle stays open: the object is loaded anyway, and `found` must not outlive it.
    free(o.names[i]);
  }
  return found;
}

int cft_guard_knows_fastdds2(void) {
  // A process with a Fast DDS 3 loaded has no 2.14 to come: no probe at every writer's creation.
  if (cft_loaded_family() != 0) return 0;
  if (__atomic_load_n(&families[0].state, __ATOMIC_ACQUIRE) == CFT_GUARD_ARMED) resolve(0, 0);
  return __atomic_load_n(&families[0].state, __ATOMIC_ACQUIRE) == CFT_GUARD_ACTIVE;
}

int cft_loaded_family(void) {
  static int cached = -1;
  int fam = __atomic_load_n(&cached, __ATOMIC_ACQUIRE);
  if (fam >= 0) return fam;
  struct loaded_list list;
  loaded_fastdds(&list);
  fam = list.count > 0 ? family_of_path(list.paths[0]) : -1;
  if (fam < 0) return 0;
  __atomic_store_n(&cached, fam, __ATOMIC_RELEASE);
  return fam;
}

bool cft_guard_env_on(int *cache, const char *env) {
  int v = __atomic_load_n(cache, __ATOMIC_RELAXED);
  if (v < 0) __atomic_store_n(cache, v = !cft_env_off(env), __ATOMIC_RELAXED);
  return v;
}

bool cft_guard_part_on(int *cache, const char *env, bool usable) {
  int v = __atomic_load_n(cache, __ATOMIC_RELAXED);
  if (v >= 0) return v;
  v = !cft_env_off(env) && usable && cft_guard_knows_fastdds2();
  __atomic_store_n(cache, v, __ATOMIC_RELAXED);
  return v;
}

long cft_guard_ms_to_ns(const char *text, long min_ms, long max_ms) {
  char *end;
  long ms = strtol(text, &end, 10);
  return end == text || *end != '\0' || ms < min_ms || ms > max_ms ? -1 : ms * 1000000L;
}

long cft_guard_env_ms(long *cache, const char *env, long fallback_ms, long min_ms, long max_ms) {
  long v = __atomic_load_n(cache, __ATOMIC_RELAXED);
  if (v >= 0) return v;
  const char *text = getenv(env);
  if (text == NULL || text[0] == '\0') {
    v = fallback_ms * 1000000L;
  } else if (strcmp(text, "off") == 0) {
    v = 0;
  } else if ((v = cft_guard_ms_to_ns(text, min_ms, max_ms)) < 0) {
    cft_say("%s=%.40s is not off or a number of ms from %ld to %ld; using %ld", env, text, min_ms,
            max_ms, fallback_ms);
    v = fallback_ms * 1000000L;
  }
  __atomic_store_n(cache, v, __ATOMIC_RELAXED);
  return v;
}

void cft_family_missing(struct family *f, int fn) {
  static int told;
  if (!__atomic_exchange_n(&told, 1, __ATOMIC_RELAXED))
    cft_say("no real definition of %s; %s", f->names[fn], f->reason);
}


// ---- load time ---------------------------------------------------------------------------------------
// A guard that arrives after Fast DDS (dlopen'ed late instead of preloaded) cannot be sure that
// Fast DDS's calls reach it, so it never claims to be active then.
// dl_iterate_phdr lists objects in load order. A Fast DDS that comes after the guard (a DT_NEEDED of
// the executable is mapped after LD_PRELOAD) is fine; one that comes before it is not.
struct order_scan {
  int self_seen;
  struct loaded_list before;
};

static int order_cb(struct dl_phdr_info *info, size_t size, void *data) {
  struct order_scan *scan = data;
  (void)size;
  if (scan->self_seen) return 1;
  uintptr_t self = (uintptr_t)&families;
  for (int i = 0; i < info->dlpi_phnum; i++) {
    const ElfW(Phdr) *ph = &info->dlpi_phdr[i];
    uintptr_t start = info->dlpi_addr + ph->p_vaddr;
    if (ph->p_type == PT_LOAD && self >= start && self < start + ph->p_memsz) {
      scan->self_seen = 1;
      return 1;
    }
  }
  return collect_cb(info, size, &scan->before);
}

__attribute__((constructor)) static void cft_guard_loaded(void) {
  struct order_scan scan = {0};
  dl_iterate_phdr(order_cb, &scan);
  struct loaded_list list = scan.before;
  if (list.count > 0) {
    loaded_after_fastdds = 1;
    snprintf(late_reason, sizeof late_reason,
             "the guard was loaded after Fast DDS (%.400s); preload it with LD_PRELOAD instead",
             list.paths[0]);
    if (cft_debug_enabled()) cft_say("%s", late_reason);
  } else if (cft_debug_enabled()) {
    cft_say("loaded; waiting for Fast DDS");
  }
}

// ---- the C API, for ctypes -----------------------------------------------------------------------------
// Resolves every family whose library is loaded by now, then reports the overall state:
// INACTIVE if the guard was loaded too late, if any family is inactive, or if a loaded
// libfastrtps/libfastdds is not one this guard knows; otherwise ACTIVE when at least one family
// is active, else ARMED.
CFT_EXPORT int cft_guard_state(void) {
  for (int i = 0; i < N_FAMILIES; i++)
    if (__atomic_load_n(&families[i].state, __ATOMIC_ACQUIRE) == CFT_GUARD_ARMED) resolve(i, 0);
  if (loaded_after_fastdds) return CFT_GUARD_INACTIVE;
  int any_active = 0;
  for (int i = 0; i < N_FAMILIES; i++) {
    int s = __atomic_load_n(&families[i].state, __ATOMIC_ACQUIRE);
    if (s == CFT_GUARD_INACTIVE) return CFT_GUARD_INACTIVE;
    any_active |= s == CFT_GUARD_ACTIVE;
  }
  return any_active ? CFT_GUARD_ACTIVE : CFT_GUARD_ARMED;
}

// 1 when the guard is loaded and either interposing a known Fast DDS or waiting for one to load;
// 0 when it is inactive (see cft_guard_reason).
CFT_EXPORT int cft_guard_is_active(void) { return cft_guard_state() != CFT_GUARD_INACTIVE; }

// Human-readable reason for the current state. The returned string is never freed or changed.
CFT_EXPORT const char *cft_guard_reason(void) {
  int state = cft_guard_state();
  if (loaded_after_fastdds) return late_reason;
  const char *active = NULL;
  for (int i = 0; i < N_FAMILIES; i++) {
    int s = __atomic_load_n(&families[i].state, __ATOMIC_ACQUIRE);
    if (s == CFT_GUARD_INACTIVE) return families[i].reason;
    if (s == CFT_GUARD_ACTIVE && active == NULL) active = families[i].reason;
  }
  if (state == CFT_GUARD_ACTIVE && active != NULL) return active;
  return "armed: no Fast DDS loaded yet; it will be interposed when it is";
}

static const struct cft_rtps_types *fastdds3_types;
void cft_fastdds3_types_loaded(const struct cft_rtps_types *types) {
  __atomic_store_n(&fastdds3_types, types, __ATOMIC_RELEASE);
}
const struct cft_rtps_types *cft_fastdds3_types(void) {
  return __atomic_load_n(&fastdds3_types, __ATOMIC_ACQUIRE);
}
