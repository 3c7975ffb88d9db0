// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The status trim's reader-side filter class (_status_trim.c), for _reader_class.c.
#ifndef CFT_ACTION_STATUS_TRIM_H_
#define CFT_ACTION_STATUS_TRIM_H_

#include "_filter_class.h"

// A client's status reader drops, in its receive thread, every sample that can change none of the
// client's goal handles, by the status table that the expression `cft_status_table = <number>`
// names (_status_trim.c). In a client's process only its own readers know the class
// (CFT_STATUS_CLASS); the guard answers it for a server's status writers otherwise
// (native/guard/_guard_status.c).
extern const struct cft_filter_grammar cft_status_grammar;

#endif  // CFT_ACTION_STATUS_TRIM_H_
