// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// Whether the client's Fast DDS 3 layer (fastdds3/, the library _cftreader_fastdds3) may be loaded
// into this process: it was built (against Fast DDS 3.3+ headers, setup.py's _fastdds_layout.h
// says so) and the Fast DDS it is linked against (its soname) is already loaded, so that loading
// it never brings a Fast DDS of its own. cft_action._rcl asks before it loads the layer.
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>

#include "_fastdds_layout.h"
#include "_filter_class.h"

#ifndef CFT_FASTDDS3_PREFILTER  // a _fastdds_layout.h that setup.py did not write
#define CFT_FASTDDS3_PREFILTER 0
#define CFT_FASTDDS3_SONAME ""
#define CFT_FASTDDS3_SOURCE "a _fastdds_layout.h that setup.py did not write"
#endif

#ifndef CFT_EXPORT
#define CFT_EXPORT __attribute__((visibility("default")))
#endif

// "" when the layer may be loaded; else why not. Called once (cft_action._rcl caches it).
CFT_EXPORT const char *cft_fastdds3_layer_refused(void) {
  static char why[600];
  if (!CFT_FASTDDS3_PREFILTER) {
    snprintf(why, sizeof why, "not built (%s)", CFT_FASTDDS3_SOURCE);
    return why;
  }
  void *loaded = dlopen(CFT_FASTDDS3_SONAME, RTLD_LAZY | RTLD_NOLOAD);
  if (loaded == NULL) {
    snprintf(why, sizeof why, "the loaded Fast DDS is not %s, the one the layer was built with",
             CFT_FASTDDS3_SONAME);
    return why;
  }
  dlclose(loaded);  // the reference NOLOAD took
  return "";
}

// The marks the layer reads and writes (native/_filter_class.h), for cft_action._rcl.
CFT_EXPORT const char *cft_fastdds3_reader_mark(void) { return CFT_READER_MARK; }
CFT_EXPORT const char *cft_fastdds3_status_reader_mark(void) { return CFT_STATUS_READER_MARK; }
CFT_EXPORT const char *cft_fastdds3_writer_mark(void) { return CFT_WRITER_MARK; }
CFT_EXPORT const char *cft_fastdds3_program_mark(void) { return CFT_PROGRAM_READER_MARK; }
