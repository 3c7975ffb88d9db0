// Preloaded before the guard into a Fast DDS 2.14 server: delays, in the discovery thread, a
// writer's processing of an *update* of a reader it already knows (a filter change) by
// SLOW_FILTER_UPDATES_MS milliseconds, so that a goal request overtakes the filter update that
// the client sent before it. First matches are not delayed.
#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define PRFI2                                                                                     \
  "_ZN8eprosima7fastdds3dds14DataWriterImpl26process_reader_filter_infoERKNS_8fastrtps4rtps6" \
  "GUID_tERKNS4_15ReaderProxyDataE"

typedef void (*prfi_fn)(void *self, const void *guid, const void *info);

enum { GUID_BYTES = 16, SEEN_MAX = 4096 };

struct pair {
  const void *writer;
  unsigned char reader[GUID_BYTES];
};

static struct pair seen[SEEN_MAX];
static int seen_count;
static pthread_mutex_t seen_lock = PTHREAD_MUTEX_INITIALIZER;

// Whether this writer has processed this reader before; remembers it if not.
static int seen_before(const void *writer, const void *guid) {
  int found = 0;
  pthread_mutex_lock(&seen_lock);
  for (int i = 0; i < seen_count && !found; i++)
    found = seen[i].writer == writer && memcmp(seen[i].reader, guid, GUID_BYTES) == 0;
  if (!found && seen_count < SEEN_MAX) {
    seen[seen_count].writer = writer;
    memcpy(seen[seen_count].reader, guid, GUID_BYTES);
    seen_count++;
  }
  pthread_mutex_unlock(&seen_lock);
  return found;
}

void slow_prfi(void *self, const void *guid, const void *info) __asm__(PRFI2);
void slow_prfi(void *self, const void *guid, const void *info) {
  static prfi_fn next;
  if (next == NULL) next = (prfi_fn)dlsym(RTLD_NEXT, PRFI2);
  if (seen_before(self, guid)) {
    const char *ms = getenv("SLOW_FILTER_UPDATES_MS");
    long delay = ms ? atol(ms) : 0;
    struct timespec ts = {delay / 1000, (delay % 1000) * 1000000L};
    nanosleep(&ts, NULL);
  }
  next(self, guid, info);
}
