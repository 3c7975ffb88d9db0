// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// Redirecting calls inside an already loaded library, for the code that is loaded with ctypes
// after Fast DDS (a preload is not an option there): a vtable slot, or a PLT slot of the GOT.
#ifndef CFT_ACTION_PATCH_H_
#define CFT_ACTION_PATCH_H_

// Replace every slot of the vtable named `vtable` (in `library`, a dlopen handle) that holds
// `from` with `to`. Returns the number of slots replaced, or -1 on failure.
int cft_patch_vtable(void *library, const char *vtable, void *from, void *to);

// Point the PLT slot through which the loaded library whose file name starts with `soname` calls
// `symbol` at `to`, if it holds `expected` (the definition it was bound to). Returns 1 if
// replaced, 0 if the slot holds something else (it was already redirected: left alone), -1 if
// there is no such library or slot.
int cft_patch_got(const char *soname, const char *symbol, void *expected, void *to);

#endif  // CFT_ACTION_PATCH_H_
