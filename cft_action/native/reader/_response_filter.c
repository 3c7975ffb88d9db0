// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// An action client's goal, cancel and result responses, filtered in its own DDS readers
// (docs/INTERNALS.md section 23). A server's response writer sends every response to every
// client's response reader; rmw_fastrtps's take then discards each response whose related sample
// identity names neither this client's response reader nor its request writer
// (`__rmw_take_response`), after the sample has woken the executor. Here each response reader of
// the library's action clients gets a reader-side data filter (`RTPSReader::data_filter_`, the
// hook Fast DDS's ContentFilteredTopic readers use) that drops, in the receive thread, the
// responses whose related identity names another participant. Those are a subset of what the take
// discards, so the client sees exactly the responses it saw before, with fewer wakes; Fast DDS
// marks a dropped sample irrelevant, so the reader acknowledges it as if it had been taken.
//
// The readers are found as they are registered (_registration.c): on a thread inside
// cft_response_filter_begin/end, a reader of a topic "rr/...Reply" (rmw_fastrtps's response
// topics) without a content filter gets the filter before the real registration, so before any
// writer is matched and any receive thread reads the member.
//
// The member's offset comes from the headers (_fastdds_layout.h), and is checked on each reader:
// its history's back pointer (`ReaderHistory::mp_reader`, set by the RTPSReader's constructor) must
// hold the reader at the headers' offset of `mp_history` moved by exactly one distance of at most
// 64 bytes (a security build's EndpointAttributes are larger), the same distance moves
// `data_filter_`, and that word must be null. Words are read through a pipe (read_word), so a
// wrong layout fails the check instead of the process.
#define _GNU_SOURCE
#include <fcntl.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "_fastdds_layout.h"
#include "_registration.h"

#define EXPORT __attribute__((visibility("default")))

// rmw_fastrtps names a service's response topic "rr/<service>Reply".
#define RESPONSE_PREFIX "rr/"
#define RESPONSE_SUFFIX "Reply"
#define MAX_MOVE 64

// One per action client, shared by its response readers. Never freed: rclpy destroys the rcl
// client once no executor uses it, which may be after the client's destroy() returns.
struct response_filter {
  const void *const *vtable;
  unsigned long dropped, passed;
};

static struct cft_install installed = CFT_INSTALL_INIT;
static __thread bool requested;                   // inside cft_response_filter_begin/end
static __thread struct response_filter *current;  // this request's, once a reader got it
static __thread int filtered_here;                // readers given the filter in this request
static __thread char refused[160];  // why a response reader of this request did not get it

#if CFT_LAYOUT_KNOWN
// IReaderDataFilter declares one pure virtual member and no destructor: its Itanium vtable is
// { is_relevant }. A received change holds the related sample identity of its inline QoS in
// write_params.sample_identity (ParameterList::updateCacheChangeFromInlineQos; the intraprocess
// and data-sharing paths copy it there too), which is what rmw_fastrtps's take compares.
static bool is_relevant(struct response_filter *self, const uint8_t *change,
                        const uint8_t *reader_guid) {
  static const uint8_t unknown[16];
  const uint8_t *related = change + CC_SAMPLE_WRITER_GUID;
  // No identity (another vendor, an older rmw): the take decides, as without the filter.
  if (memcmp(related, unknown, sizeof unknown) == 0 || memcmp(related, reader_guid, 12) == 0) {
    __atomic_fetch_add(&self->passed, 1, __ATOMIC_RELAXED);
    return true;
  }
  __atomic_fetch_add(&self->dropped, 1, __ATOMIC_RELAXED);
  return false;
}

static const void *const filter_vtable[] = {(const void *)is_relevant};

// A word of this process's memory, or false where it cannot be read: write(2) from an address
// that is not mapped readable fails with EFAULT where a load would fault. (process_vm_readv would
// do too, but the seccomp profiles of containers commonly forbid it.) The system call itself, not
// libc's write: a sanitizer's interceptor of write reads the source's shadow memory first, which a
// probed address need not have (make test-asan: SEGV in the interceptor).
static bool read_word(const int fds[2], uintptr_t address, uintptr_t *word) {
  return syscall(SYS_write, fds[1], (const void *)address, sizeof *word) == (long)sizeof *word &&
         read(fds[0], word, sizeof *word) == (ssize_t)sizeof *word;
}

// Whether a fixed_string<255> (the headers' layout: the characters, then their count) holds a
// response topic's name.
static bool is_response_topic(const char *name) {
  size_t length, prefix = strlen(RESPONSE_PREFIX), suffix = strlen(RESPONSE_SUFFIX);
  memcpy(&length, name + STRING255_LENGTH, sizeof length);
  return length < STRING255_LENGTH && name[length] == '\0' && length > prefix + suffix &&
         strncmp(name, RESPONSE_PREFIX, prefix) == 0 &&
         strcmp(name + length - suffix, RESPONSE_SUFFIX) == 0;
}

// The address of the reader's data_filter_, or 0 after saying why in `refused`.
static uintptr_t data_filter_member(uintptr_t reader) {
  int fds[2];
  if (pipe2(fds, O_CLOEXEC | O_NONBLOCK) != 0) {
    snprintf(refused, sizeof refused, "no pipe to read the reader's layout through");
    return 0;
  }
  int found = 0;
  uintptr_t member = 0, value = 1;
  for (uintptr_t move = 0; move <= MAX_MOVE; move += 4) {
    uintptr_t history, back;
    if (read_word(fds, reader + RR_HISTORY + move, &history) && history != 0 &&
        read_word(fds, history + RH_READER, &back) && back == reader) {
      found++;
      member = reader + RR_DATA_FILTER + move;
    }
  }
  bool unset = found == 1 && read_word(fds, member, &value) && value == 0;
  close(fds[0]);
  close(fds[1]);
  if (found != 1) {
    snprintf(refused, sizeof refused,
             "the reader's history does not point back to it at exactly one offset near the "
             "headers' (%d found): the loaded Fast DDS has another RTPSReader layout", found);
    return 0;
  }
  if (!unset) {
    snprintf(refused, sizeof refused, "the reader already has a data filter");
    return 0;
  }
  return member;
}

// This request's filter, made at its first reader; NULL after saying why in `refused`.
static struct response_filter *request_filter(void) {
  if (current == NULL && (current = calloc(1, sizeof *current)) != NULL)
    current->vtable = filter_vtable;
  if (current == NULL) snprintf(refused, sizeof refused, "no memory for the filter");
  return current;
}

static void registering(void *reader, const char *topic_name, const void *content_filter) {
  if (requested && content_filter == NULL && is_response_topic(topic_name)) {
    uintptr_t member = data_filter_member((uintptr_t)reader);
    struct response_filter *filter = member != 0 ? request_filter() : NULL;
    if (filter != NULL) {
      // Not registered yet: no writer is matched, so no receive thread reads the member.
      *(struct response_filter **)member = filter;
      filtered_here++;
    }
  }
}
#endif

static int install(struct cft_install *once) {
#if CFT_LAYOUT_KNOWN
  return cft_registration_install(once, registering);
#else
  return cft_install_fail(once, -5, "no Fast DDS layout at build time", CFT_LAYOUT_SOURCE);
#endif
}

// 0 once response readers created inside cft_response_filter_begin/end get the filter; < 0 if
// that cannot be arranged (cft_response_filter_error says why). Later calls return the first
// result.
EXPORT int cft_response_filter_install(void) { return cft_install_once(&installed, install); }

EXPORT const char *cft_response_filter_error(void) { return installed.error; }

// Around the creation of an action client (rcl_action_client_init) on this thread.
EXPORT void cft_response_filter_begin(void) {
  requested = true;
  current = NULL;
  filtered_here = 0;
  refused[0] = '\0';
}

// Ends the request; returns its filter (NULL if no reader got one), and in `*readers` how many
// response readers got it.
EXPORT void *cft_response_filter_end(int *readers) {
  requested = false;
  *readers = filtered_here;
  return current;
}

// Why a response reader of the last request did not get the filter; empty if none was refused.
EXPORT const char *cft_response_filter_refused(void) { return refused; }

// The responses a filter dropped and passed.
EXPORT void cft_response_filter_counts(const struct response_filter *filter,
                                       unsigned long *counts) {
  counts[0] = __atomic_load_n(&filter->dropped, __ATOMIC_RELAXED);
  counts[1] = __atomic_load_n(&filter->passed, __ATOMIC_RELAXED);
}
