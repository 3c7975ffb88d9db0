// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// What _guard.c (the locks, and the interposition of the DataWriterImpl members) offers the other
// parts of the server guard. The guard is _guard.c, _guard_filter.c (the DDS-SQL accelerator,
// _guard_filter.h), _guard_writer_qos.c (the writers' limit of filtered readers),
// _guard_heartbeats.c (which readers a filtered writer's HEARTBEATs and GAPs reach),
// _guard_replies.c (an action's replies go to the requesting participant, _guard_replies.h),
// _guard_log.c (logging, _guard_log.h) and the filter classes (_filter_class.c, _uuid_program.c,
// _node_program.c); setup.py builds them into one library. Calls go one way: _guard_writer_qos.c
// and _guard_heartbeats.c -> _guard.c -> _guard_replies.c -> _guard_filter.c and _filter_class.c,
// and every part -> _guard_log.c (_guard_replies.c also uses _guard.c's cft_guard_real and
// cft_guard_knows_fastdds2, as _guard_heartbeats.c does).
#ifndef CFT_ACTION_GUARD_H_
#define CFT_ACTION_GUARD_H_

#include <stdbool.h>

#ifndef CFT_EXPORT
#define CFT_EXPORT __attribute__((visibility("default")))
#endif

// 1 when _guard.c locks the Fast DDS 2.14 it knows, whose layouts the other parts may then use.
// Decides the family's state if it is not decided yet: call it only once Fast DDS is loaded.
int cft_guard_knows_fastdds2(void);

// Whether a part of the guard that `env` can turn off ("off" or "0") is on: `usable` (its layouts
// are known) and the guard locks the Fast DDS 2.14 it knows. Decided once, cached in *cache (-1:
// not yet).
bool cft_guard_part_on(int *cache, const char *env, bool usable);

// `text` as a number of ms from `min_ms` to `max_ms`, in ns; -1 if it is not one.
long cft_guard_ms_to_ns(const char *text, long min_ms, long max_ms);

// The environment variable `env` as a period of `min_ms` to `max_ms` ms, in ns: `fallback_ms`'s
// when unset or empty, 0 when "off"; anything else is said once and gives the fallback. Decided
// once, cached in *cache (-1: not yet).
long cft_guard_env_ms(long *cache, const char *env, long fallback_ms, long min_ms, long max_ms);

// The definition of `name` in the loaded library `soname` (rmw loads Fast DDS and its own
// libraries RTLD_LOCAL, outside the global scope), else the next one after the guard's; NULL if
// there is none. Cached in *cache (release) on the first call; the library's handle is kept, since
// the pointer must not outlive it.
void *cft_guard_real(void **cache, const char *soname, const char *name);

#endif  // CFT_ACTION_GUARD_H_
