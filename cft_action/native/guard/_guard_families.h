// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The Fast DDS families the server guard knows (_guard_families.c): one per mangling (Fast DDS
// major version), with the names of the members that _guard.c interposes, where their real
// definitions are, and whether the guard locks them. And what every part of the guard asks of it.
// The guard is _guard.c (the locks and the interposed DataWriterImpl members), _guard_families.c,
// _guard_filter.c (the DDS-SQL accelerator), _guard_writer_qos.c (the writers' limit of filtered
// readers), _guard_heartbeats.c (which readers a filtered writer's HEARTBEATs and GAPs reach),
// _guard_replies.c (an action's replies go to the requesting participant), _guard_status.c (the
// status filter), _guard_goals.c (whose goal is it), _guard_feedback.c (the feedback verdict of
// Fast DDS 3), _guard_endpoints.c (rcl's services and feedback publishers, handed to the loaded
// family's layer), _guard_log.c (logging) and the filter classes (_filter_class.c,
// _uuid_program.c, _node_program.c, _rate_program.c); setup.py builds them into one library. The
// Fast DDS 3.3+ layer, fastdds3/ (C++, public API only), is a library of its own that
// _guard_endpoints.c loads. Calls go one way: _guard.c -> _guard_replies.c -> _guard_filter.c ->
// _guard_status.c and _filter_class.c; _guard_endpoints.c -> _guard_replies.c, _guard_feedback.c
// and fastdds3/ (which calls back only the decisions it is given); _guard_status.c and
// _guard_feedback.c -> _guard_goals.c; _guard_writer_qos.c and _guard_heartbeats.c ->
// _guard_status.c; every part -> _guard_families.c -> _guard_log.c.
#ifndef CFT_ACTION_GUARD_FAMILIES_H_
#define CFT_ACTION_GUARD_FAMILIES_H_

#include <pthread.h>
#include <stdbool.h>

#include "fastdds3/_rtps_types.h"

#ifndef CFT_EXPORT
#define CFT_EXPORT __attribute__((visibility("default")))
#endif

// ---- public state codes (mirrored in cft_action/guard.py) ---------------------------------------
#define CFT_GUARD_ARMED 0        // preloaded; no Fast DDS resolved yet (none loaded, or not used)
#define CFT_GUARD_ACTIVE 1       // interposing a known Fast DDS: writes and filter changes locked
#define CFT_GUARD_INACTIVE 2     // unknown Fast DDS version, or loaded too late: calls go straight
                                 // through (or, if the real function is missing, fail safely)

// ---- the interposed functions ---------------------------------------------------------------------
// The first three are locked; the fourth, DDSFilterExpression::evaluate (a virtual member, whose
// vtable slot is a relocation against its exported name), is where _guard_filter.c answers
// uuid-only filters without deserializing the sample; the fifth,
// DomainParticipantImpl::find_content_filter_factory, gives the writers the library's own filter
// classes (_filter_class.h); the sixth, DataWriterImpl::is_relevant (IReaderDataFilter's member,
// virtual too: the slots of DataWriterImpl's vtable and of its statistics subclass's are
// R_X86_64_64 relocations against its exported name, no thunk), answers for the readers of those
// classes that _guard_filter.c keeps out of Fast DDS's filter collection, so that no filter
// signature is written for them, and for the readers that an action's reply is not for
// (_guard_replies.c). Only Fast DDS 2.14 has the last three here, but for the fifth, whose mangled
// name is the same in 3.x: there it only calls the real member (cft_find).
enum { FN_PCNC = 0, FN_PRFI = 1, FN_RRF = 2, FN_LOCKED = 3, FN_EVAL = 3, FN_FIND = 4, FN_REL = 5,
       FN_COUNT = 6 };

// Fast DDS 2.x (libfastrtps), verified on 2.14.5 (ROS 2 Jazzy wheels), on 2.14.6 built with
// SECURITY=ON (apt's) and on the 2.14.x head (docs/COMPATIBILITY.md).
#define PCNC2 "_ZN8eprosima7fastdds3dds14DataWriterImpl25perform_create_new_changeENS_8fastrtps4rtps12ChangeKind_tEPvRNS4_11WriteParamsERKNS4_16InstanceHandle_tE"
#define PRFI2 "_ZN8eprosima7fastdds3dds14DataWriterImpl26process_reader_filter_infoERKNS_8fastrtps4rtps6GUID_tERKNS4_15ReaderProxyDataE"
#define RRF2 "_ZN8eprosima7fastdds3dds14DataWriterImpl20remove_reader_filterERKNS_8fastrtps4rtps6GUID_tE"
// The same name in Fast DDS 2 and 3: one definition serves both (cft_find).
#define FIND "_ZN8eprosima7fastdds3dds21DomainParticipantImpl27find_content_filter_factoryEPKc"
#define EVAL2 "_ZNK8eprosima7fastdds3dds12DDSSQLFilter19DDSFilterExpression8evaluateERKNS_8fastrtps4rtps19SerializedPayload_tERKNS1_14IContentFilter16FilterSampleInfoERKNS5_6GUID_tE"
#define REL2 "_ZNK8eprosima7fastdds3dds14DataWriterImpl11is_relevantERKNS_8fastrtps4rtps13CacheChange_tERKNS4_6GUID_tE"

// Fast DDS 3.x (libfastdds), verified on libfastdds.so.3.2 from the ROS 2 Kilted wheels and on a
// 3.6.2 build with Lyrical's options (docs/COMPATIBILITY.md): the same names in both.
#define PCNC3 "_ZN8eprosima7fastdds3dds14DataWriterImpl25perform_create_new_changeENS0_4rtps12ChangeKind_tEPKvRNS3_11WriteParamsERKNS3_16InstanceHandle_tE"
#define PRFI3 "_ZN8eprosima7fastdds3dds14DataWriterImpl26process_reader_filter_infoERKNS0_4rtps6GUID_tERKNS3_28SubscriptionBuiltinTopicDataE"
#define RRF3 "_ZN8eprosima7fastdds3dds14DataWriterImpl20remove_reader_filterERKNS0_4rtps6GUID_tE"

// One family per mangling (Fast DDS major version). Its state moves once, from ARMED to ACTIVE
// or INACTIVE, under resolve_lock; `state` is read without the lock (acquire), and everything
// else is written before the release store and never changed afterwards.
#define KNOWN_SONAMES 3
struct family {
  const char *label;
  const char *known_sonames[KNOWN_SONAMES];  // the versions whose ABI and behaviour were checked,
                                             // the newest first (NULL ends)
  const char *prefix;         // basename prefix of any library of this family
  const char *names[FN_COUNT];
  void *real[FN_COUNT];
  int state;
  pthread_mutex_t resolve_lock;
  char reason[512];
};

// The family `fam` (0: Fast DDS 2, 1: Fast DDS 3), its state decided (from a call: a family whose
// library is not loaded is then inactive, its members missing).
struct family *cft_family_ready(int fam);

// The family of the Fast DDS loaded in this process (the first found), for a member whose name
// both families share; 0 when none is found.
int cft_loaded_family(void);

// Says once that the family has no real definition of its member `fn`, and why.
void cft_family_missing(struct family *f, int fn);

// 1 when the guard locks the Fast DDS 2.14 it knows, whose layouts the other parts may then use.
// Asked from the guard's other parts, also in a process of another family: family 0 is decided
// only once its library is loaded (a probe, as cft_guard_state's), never declared missing.
int cft_guard_knows_fastdds2(void);

// Whether a part of the guard that `env` can turn off ("off" or "0") is on: `usable` (its layouts
// are known) and the guard locks the Fast DDS 2.14 it knows. Decided once, cached in *cache (-1:
// not yet).
bool cft_guard_part_on(int *cache, const char *env, bool usable);

// Whether the environment variable `env` leaves a part on (it is not "off" or "0"), in any family.
// Decided once, cached in *cache (-1: not yet).
bool cft_guard_env_on(int *cache, const char *env);

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

// The definition of `name` in the library that called the interposed member `name` (the call's
// `return_address` is in it): for Fast DDS's own members, which only Fast DDS calls, whichever
// version and soname is loaded. Else the next one after the guard's; NULL if none. Cached as
// cft_guard_real's.
void *cft_guard_real_in_caller(void **cache, const char *name, const void *return_address);

// The definition of `name` in a loaded object other than the guard, one whose path holds `prefer`
// if there is one (NULL: the first found); NULL if none. For the libraries that ROS loads in a local
// scope, outside the global one that RTLD_NEXT searches (rcl, rmw_implementation, which the wheels
// rename, rmw_fastrtps_cpp). Not under the loader's lock: call it outside Fast DDS's callbacks.
void *cft_guard_loaded_symbol(const char *name, const char *prefer);

// The Fast DDS 3 layer's reading of RTPS types (fastdds3/_rtps_types.h), for the parts that read a
// change, a sequence number set or a writer on Fast DDS 3: given by _guard_endpoints.c once it
// has loaded the layer; NULL before, and where the layer is not used.
void cft_fastdds3_types_loaded(const struct cft_rtps_types *types);
const struct cft_rtps_types *cft_fastdds3_types(void);

#endif  // CFT_ACTION_GUARD_FAMILIES_H_
