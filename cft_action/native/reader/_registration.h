// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The readers of this process, looked at as Fast DDS registers them (_registration.c), for the
// parts that adjust the readers of the library's action clients: _response_filter.c and
// _status_acks.c. Each part gives its own function when it installs (so calls go one way, from
// the parts into this file), which is then called with the RTPSReader, its topic name and its
// ContentFilterProperty (NULL without a filter) before the real registration, so before any
// writer is matched and any receive thread reads the reader.
#ifndef CFT_ACTION_REGISTRATION_H_
#define CFT_ACTION_REGISTRATION_H_

#include "_patch.h"

typedef void (*cft_registering_fn)(void *reader, const char *topic_name,
                                   const void *content_filter);

// 0 once every reader registered from now on is shown to `part`; < 0 after recording in `once` why
// not (the caller's cft_install record: each part installs through this, once).
int cft_registration_install(struct cft_install *once, cft_registering_fn part);

#endif  // CFT_ACTION_REGISTRATION_H_
