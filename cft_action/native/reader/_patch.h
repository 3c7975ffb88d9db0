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
// `symbol` at `to`, if it holds `expected` (the definition it was bound to) or is not bound yet
// (lazy binding: it points into that library's own PLT). Returns 1 if
// replaced, 0 if the slot holds something else (it was already redirected: left alone), -1 if
// there is no such library or slot.
int cft_patch_got(const char *soname, const char *symbol, void *expected, void *to);

// An installation that runs at most once per process: the first cft_install_once runs `install`,
// and every call returns its status (0 or more: installed; below 0: failed, `error` says why).
#include <pthread.h>
struct cft_install {
  pthread_mutex_t mutex;
  int status;  // 1: not tried yet
  char error[256];
};
#define CFT_INSTALL_INIT {PTHREAD_MUTEX_INITIALIZER, 1, ""}
int cft_install_once(struct cft_install *once, int (*install)(struct cft_install *));
// Records why the installation failed; returns `status`.
int cft_install_fail(struct cft_install *once, int status, const char *what, const char *detail);

// For an install function: the already loaded library whose soname is `soname`, and the address
// of each of its `count` `names` (searched from that library on, as its own PLT binds them) in
// `found`. Returns the library's dlopen handle, or NULL after recording why: `*status` is then -1
// (the library is not loaded) or -2 (a name is not found).
#include <stddef.h>
void *cft_resolve(struct cft_install *once, const char *soname, const char *const *names,
                  size_t count, void **found, int *status);

#endif  // CFT_ACTION_PATCH_H_
