// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// A Fast DDS 2.14 reliable endpoint's protocol times: a StatefulReader's ReaderTimes times_ (the
// client's status readers answer HEARTBEATs at once, reader/_status_acks.c) and a StatefulWriter's
// WriterTimes m_times (a guarded server's status writers heartbeat more often, guard/
// _guard_status.c). Both classes begin with a vtable pointer (an inline virtual destructor), then
// Duration_t members; StatefulReader::updateTimes and StatefulWriter::updateTimes (exported,
// public) set them, with the endpoint's mutex, for the endpoint and its matched proxies.
#ifndef CFT_ACTION_ENDPOINT_TIMES_H_
#define CFT_ACTION_ENDPOINT_TIMES_H_

#include <stddef.h>
#include <stdint.h>

// An Itanium vtable pointer points past the vtable's offset-to-top and typeinfo words.
#define CFT_VTABLE_START (2 * sizeof(void *))

// Fast DDS 2.14's Duration_t: seconds, then nanoseconds.
struct cft_duration {
  int32_t seconds;
  uint32_t nanosec;
};

// The address of the times member of `endpoint`, a `endpoint_size`-byte object (the headers'
// size, which a larger build only extends) whose headers put a `times_size`-byte member at
// `offset`: the one word at most 64 bytes past `offset` (a security build's EndpointAttributes
// are larger) that points into the vtable named `times_vtable` (told by the symbol's name,
// dladdr: with an inline destructor every library that constructs one may carry a copy of the
// vtable, and the constructor binds to the first copy in the lookup order). 0 where not exactly
// one word does; *found says how many did.
uintptr_t cft_endpoint_times(uintptr_t endpoint, size_t endpoint_size, size_t offset,
                             size_t times_size, const char *times_vtable, int *found);

#endif  // CFT_ACTION_ENDPOINT_TIMES_H_
