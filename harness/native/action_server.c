// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// A Fibonacci action server in C over rcl_action, as production servers run: K action servers in
// one process (each its own node, action name and executor thread, as Nav2's composed servers),
// a thread per goal publishing its feedback, and every rcl_action_* call of a server under that
// server's recursive mutex, as rclcpp_action's Server does. Different servers publish at once.
//
// Usage: action_server ACTION PERIOD_S [--servers K] [--pad N] [--depth N|all]
//                      [--feedback-depth N] [--result-timeout S] [--hold-goals N]
//
// With K = 1 the action is ACTION; with K > 1 the actions are ACTION_0 ... ACTION_<K-1>. The
// protocol is harness/server.py's (harness/c_server.py builds and starts this program):
// - goal `order` is the number of feedback messages the goal gets (a negative order is
//   rejected; cancels are accepted); each feedback `sequence` is [k, seconds, nanoseconds] + [0] *
//   PAD, the message's index in its goal and its wall-clock publish time; the first is published
//   at once by the goal's thread, the others every PERIOD_S on an absolute schedule; the goal
//   succeeds one period after its last feedback, with the result [feedback messages published];
// - `--depth N` makes the goal, cancel and result services and the feedback writer keep-last N,
//   reliable; `--depth all` keep-all (1000-sample hint); `--feedback-depth N` the feedback writer
//   alone; otherwise rcl_action's defaults; `--result-timeout S` as rclpy's (default 900 s);
// - `--hold-goals N`: goals of positive order wait after their first feedback until N of them
//   (over all servers) were accepted, or the command `release` came;
// - it prints `ACTIONS <json>` (the action names), `STATUS <guard active> <guard status>` and
//   `READY`; `STATS <json>` replies to `stats`, `GOALS <json>` (feedback published per goal UUID in
//   hex) to `goals`; end of input stops it cleanly (exit 0).
// The STATS counters of the guard (when it is preloaded) are raw arrays of GUARD_SLOTS values, in
// the order of cft_action.guard's names, which harness/c_server.py puts on them.

#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include <action_msgs/msg/goal_status.h>
#include <rcl/error_handling.h>
#include <rcl/rcl.h>
#include <rcl_action/rcl_action.h>
#include <rosidl_runtime_c/primitives_sequence_functions.h>
#include <test_msgs/action/fibonacci.h>

#define HEADER 3         // [k, seconds, nanoseconds] before the padding
#define GUARD_SLOTS 16   // guard counters read per family (those past the end read 0)
#define THREAD_STACK (256 * 1024)

typedef test_msgs__action__Fibonacci_SendGoal_Request goal_request_t;
typedef test_msgs__action__Fibonacci_SendGoal_Response goal_response_t;
typedef test_msgs__action__Fibonacci_GetResult_Request result_request_t;
typedef test_msgs__action__Fibonacci_GetResult_Response result_response_t;
typedef test_msgs__action__Fibonacci_FeedbackMessage feedback_message_t;

struct server;

typedef struct goal {
  struct server *server;
  uint8_t uuid[16];
  int32_t order;
  rcl_action_goal_handle_t *handle;  // owned by rcl_action; NULL once the goal is terminal
  int8_t status;                     // the terminal status, once terminal
  int32_t published;
  rmw_request_id_t *waiting;         // result requests that wait for the goal's end
  size_t n_waiting, cap_waiting;
  pthread_t thread;
  bool has_thread;
  struct goal *next;
} goal_t;

typedef struct server {
  int index;
  char action[256];
  pthread_mutex_t mutex;  // recursive: every rcl_action_* call of this server, and its goals
  rcl_node_t node;
  rcl_clock_t clock;
  rcl_action_server_t action_server;
  rcl_wait_set_t wait_set;
  rcl_guard_condition_t wake;
  pthread_t executor;
  goal_t *goals;
  unsigned long published, accepted, active, peak_active, rejected, goal_requests,
      goal_responses, goal_response_errors, result_requests, result_responses,
      result_response_errors, cancel_requests, late_ticks, publish_errors;
} server_t;

// ---- options and process state ------------------------------------------------------------------
static struct {
  const char *action;
  double period;
  int servers, pad, hold_goals;
  const char *depth;
  int feedback_depth;
  double result_timeout;
} opt = {NULL, 0.0, 1, 0, 0, NULL, 0, 900.0};

static rcl_context_t context;
static server_t *servers;
static volatile bool running = true;
static pthread_mutex_t state_lock = PTHREAD_MUTEX_INITIALIZER;  // running, holding, output
static pthread_cond_t state_changed;                            // CLOCK_MONOTONIC
static int held_accepted;
static bool released;
static struct timespec started;

static void die(const char *what) {
  fprintf(stderr, "action_server: %s: %s\n", what, rcl_get_error_string().str);
  fflush(stderr);
  exit(1);
}

static void check(rcl_ret_t ret, const char *what) {
  if (ret != RCL_RET_OK) die(what);
}

// A failure while running is reported and counted, never fatal: a server goes on as rclcpp's does.
static bool ok(rcl_ret_t ret, const char *what) {
  if (ret == RCL_RET_OK) return true;
  fprintf(stderr, "action_server: %s failed (%d): %s\n", what, (int)ret, rcl_get_error_string().str);
  rcl_reset_error();
  return false;
}

static double seconds_since(const struct timespec *from) {
  struct timespec now;
  clock_gettime(CLOCK_MONOTONIC, &now);
  return (double)(now.tv_sec - from->tv_sec) + (double)(now.tv_nsec - from->tv_nsec) * 1e-9;
}

static void add_seconds(struct timespec *t, double s) {
  long long ns = (long long)t->tv_nsec + (long long)(s * 1e9);
  t->tv_sec += (time_t)(ns / 1000000000LL);
  t->tv_nsec = (long)(ns % 1000000000LL);
}

// ---- a growing string, for the JSON lines -------------------------------------------------------
typedef struct {
  char *data;
  size_t size, cap;
} buf_t;

static void put(buf_t *b, const char *format, ...) {
  for (;;) {
    va_list args;
    va_start(args, format);
    int n = vsnprintf(b->data + b->size, b->cap - b->size, format, args);
    va_end(args);
    if (n >= 0 && (size_t)n < b->cap - b->size) {
      b->size += (size_t)n;
      return;
    }
    b->cap = b->cap * 2 + (size_t)(n > 0 ? n : 0) + 256;
    b->data = realloc(b->data, b->cap);
    if (b->data == NULL) abort();
  }
}

static void put_json_string(buf_t *b, const char *s) {
  put(b, "\"");
  for (; *s; s++) {
    unsigned char c = (unsigned char)*s;
    if (c == '"' || c == '\\') put(b, "\\%c", c);
    else if (c < 0x20) put(b, "\\u%04x", c);
    else put(b, "%c", c);
  }
  put(b, "\"");
}

static void emit(buf_t *b) {
  pthread_mutex_lock(&state_lock);
  fwrite(b->data, 1, b->size, stdout);
  fputc('\n', stdout);
  fflush(stdout);
  pthread_mutex_unlock(&state_lock);
  free(b->data);
}

static void put_uuid(buf_t *b, const uint8_t uuid[16]) {
  put(b, "\"");
  for (int i = 0; i < 16; i++) put(b, "%02x", uuid[i]);
  put(b, "\"");
}

// ---- the guard, when it is preloaded (its C API is then in the global scope) --------------------
static void put_guard(buf_t *b) {
  const char *(*reason)(void) = (const char *(*)(void))dlsym(RTLD_DEFAULT, "cft_guard_reason");
  put(b, "\"guard\":");
  put_json_string(b, reason ? reason() : "not preloaded: cft_guard_reason is not in the global "
                                         "symbol scope");
  static const char *const families[][2] = {
      {"guard_calls", "cft_guard_call_count"},
      {"guard_filter", "cft_guard_filter_count"},
      {"guard_filter_class", "cft_guard_filter_class_count"},
      {"guard_writers", "cft_guard_writer_qos_count"},
      {"guard_heartbeats", "cft_guard_heartbeat_count"},
      {"guard_status", "cft_guard_status_count"}};
  for (size_t f = 0; f < sizeof families / sizeof families[0]; f++) {
    unsigned long (*count)(int) = (unsigned long (*)(int))dlsym(RTLD_DEFAULT, families[f][1]);
    put(b, ",\"%s\":[", families[f][0]);
    for (int i = 0; count != NULL && i < GUARD_SLOTS; i++) put(b, "%s%lu", i ? "," : "", count(i));
    put(b, "]");
  }
}

static void print_guard_status(void) {
  int (*state)(void) = (int (*)(void))dlsym(RTLD_DEFAULT, "cft_guard_state");
  const char *(*reason)(void) = (const char *(*)(void))dlsym(RTLD_DEFAULT, "cft_guard_reason");
  // cft_guard_state: 0 armed, 1 active, 2 inactive (cft_action/native/guard/_guard.c).
  bool active = state != NULL && state() != 2;
  printf("STATUS %s %s\n", active ? "True" : "False",
         reason ? reason() : "not preloaded: cft_guard_state is not in the global symbol scope");
  fflush(stdout);
}

// ---- goals ----------------------------------------------------------------------------------------
// With the server's mutex held.
static goal_t *find_goal(server_t *s, const uint8_t uuid[16]) {
  for (goal_t *g = s->goals; g != NULL; g = g->next)
    if (memcmp(g->uuid, uuid, 16) == 0) return g;
  return NULL;
}

static void publish_status(server_t *s) {
  rcl_action_goal_status_array_t status = rcl_action_get_zero_initialized_goal_status_array();
  if (ok(rcl_action_get_goal_status_array(&s->action_server, &status), "get_goal_status_array")) {
    ok(rcl_action_publish_status(&s->action_server, &status.msg), "publish_status");
    ok(rcl_action_goal_status_array_fini(&status), "goal_status_array_fini");
  }
}

static void send_result(server_t *s, rmw_request_id_t *header, int8_t status, int32_t published) {
  result_response_t response;
  test_msgs__action__Fibonacci_GetResult_Response__init(&response);
  response.status = status;
  if (status != action_msgs__msg__GoalStatus__STATUS_UNKNOWN) {
    rosidl_runtime_c__int32__Sequence__fini(&response.result.sequence);
    rosidl_runtime_c__int32__Sequence__init(&response.result.sequence, 1);
    response.result.sequence.data[0] = published;
  }
  if (ok(rcl_action_send_result_response(&s->action_server, header, &response), "send_result"))
    s->result_responses++;
  else
    s->result_response_errors++;
  test_msgs__action__Fibonacci_GetResult_Response__fini(&response);
}

// The goal's end, with the server's mutex held.
static void finish(goal_t *g, bool canceled) {
  server_t *s = g->server;
  g->status = canceled ? action_msgs__msg__GoalStatus__STATUS_CANCELED
                       : action_msgs__msg__GoalStatus__STATUS_SUCCEEDED;
  ok(rcl_action_update_goal_state(g->handle, canceled ? GOAL_EVENT_CANCELED : GOAL_EVENT_SUCCEED),
     "update_goal_state");
  g->handle = NULL;  // rcl_action may finalize it once it expires
  s->active--;
  publish_status(s);
  for (size_t i = 0; i < g->n_waiting; i++) send_result(s, &g->waiting[i], g->status, g->published);
  g->n_waiting = 0;
  ok(rcl_action_notify_goal_done(&s->action_server), "notify_goal_done");
}

static bool cancel_requested(goal_t *g) {
  rcl_action_goal_state_t state = GOAL_STATE_UNKNOWN;
  return ok(rcl_action_goal_handle_get_status(g->handle, &state), "goal_handle_get_status") &&
         state == GOAL_STATE_CANCELING;
}

// Sleep until `due` or the end of the process; false at the end.
static bool sleep_until(const struct timespec *due) {
  pthread_mutex_lock(&state_lock);
  while (running && pthread_cond_timedwait(&state_changed, &state_lock, due) != ETIMEDOUT) {
  }
  bool on = running;
  pthread_mutex_unlock(&state_lock);
  return on;
}

static bool wait_for_release(void) {
  pthread_mutex_lock(&state_lock);
  while (running && !released) pthread_cond_wait(&state_changed, &state_lock);
  bool on = running;
  pthread_mutex_unlock(&state_lock);
  return on;
}

static void *run_goal(void *arg) {
  goal_t *g = arg;
  server_t *s = g->server;
  feedback_message_t message;
  test_msgs__action__Fibonacci_FeedbackMessage__init(&message);
  memcpy(message.goal_id.uuid, g->uuid, 16);
  rosidl_runtime_c__int32__Sequence__fini(&message.feedback.sequence);
  rosidl_runtime_c__int32__Sequence__init(&message.feedback.sequence, (size_t)(HEADER + opt.pad));
  struct timespec due;
  clock_gettime(CLOCK_MONOTONIC, &due);
  bool canceled = false;
  for (int32_t k = 0; k < g->order && !canceled; k++) {
    pthread_mutex_lock(&s->mutex);
    canceled = cancel_requested(g);
    if (!canceled) {
      struct timespec now;
      clock_gettime(CLOCK_REALTIME, &now);
      int32_t *sequence = message.feedback.sequence.data;
      sequence[0] = k;
      sequence[1] = (int32_t)now.tv_sec;
      sequence[2] = (int32_t)now.tv_nsec;
      if (ok(rcl_action_publish_feedback(&s->action_server, &message), "publish_feedback")) {
        g->published = k + 1;
        s->published++;
      } else {
        s->publish_errors++;
      }
    }
    pthread_mutex_unlock(&s->mutex);
    if (k == 0 && opt.hold_goals > 0 && !wait_for_release()) goto stopped;
    add_seconds(&due, opt.period);
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    double behind = (double)(now.tv_sec - due.tv_sec) + (double)(now.tv_nsec - due.tv_nsec) * 1e-9;
    if (behind > opt.period) {  // restart the schedule rather than publish a burst
      pthread_mutex_lock(&s->mutex);
      s->late_ticks++;
      pthread_mutex_unlock(&s->mutex);
      due = now;
    }
    if (!sleep_until(&due)) goto stopped;
  }
  pthread_mutex_lock(&s->mutex);
  finish(g, canceled || cancel_requested(g));
  pthread_mutex_unlock(&s->mutex);
stopped:
  test_msgs__action__Fibonacci_FeedbackMessage__fini(&message);
  return NULL;
}

// ---- the executor's work, each with the server's mutex held ---------------------------------------
// Whether a take gave a request: false when there was none (its error reset) or it failed (said).
static bool taken(rcl_ret_t ret, const char *what) {
  if (ret == RCL_RET_ACTION_SERVER_TAKE_FAILED) {
    rcl_reset_error();
    return false;
  }
  return ok(ret, what);
}

static void take_goal_request(server_t *s) {
  rmw_request_id_t header;
  goal_request_t request;
  test_msgs__action__Fibonacci_SendGoal_Request__init(&request);
  rcl_ret_t ret = rcl_action_take_goal_request(&s->action_server, &header, &request);
  if (!taken(ret, "take_goal_request")) return;
  s->goal_requests++;
  goal_response_t response;
  test_msgs__action__Fibonacci_SendGoal_Response__init(&response);
  response.accepted = request.goal.order >= 0;
  goal_t *g = NULL;
  if (response.accepted) {
    rcl_action_goal_info_t info = rcl_action_get_zero_initialized_goal_info();
    memcpy(info.goal_id.uuid, request.goal_id.uuid, 16);
    rcl_time_point_value_t now = 0;
    ok(rcl_clock_get_now(&s->clock, &now), "clock_get_now");
    info.stamp.sec = (int32_t)(now / 1000000000LL);
    info.stamp.nanosec = (uint32_t)(now % 1000000000LL);
    response.stamp = info.stamp;
    rcl_action_goal_handle_t *handle = rcl_action_accept_new_goal(&s->action_server, &info);
    if (handle == NULL) {
      ok(RCL_RET_ERROR, "accept_new_goal");
      response.accepted = false;
    } else {
      g = calloc(1, sizeof *g);
      g->server = s;
      memcpy(g->uuid, request.goal_id.uuid, 16);
      g->order = request.goal.order;
      g->handle = handle;
      g->status = action_msgs__msg__GoalStatus__STATUS_EXECUTING;
      g->next = s->goals;
      s->goals = g;
    }
  }
  if (ok(rcl_action_send_goal_response(&s->action_server, &header, &response), "send_goal_response"))
    s->goal_responses++;
  else
    s->goal_response_errors++;
  if (g == NULL) {
    s->rejected++;
  } else {
    ok(rcl_action_update_goal_state(g->handle, GOAL_EVENT_EXECUTE), "update_goal_state");
    publish_status(s);
    s->accepted++;
    s->active++;
    if (s->active > s->peak_active) s->peak_active = s->active;
    if (opt.hold_goals > 0 && g->order > 0) {
      pthread_mutex_lock(&state_lock);
      if (++held_accepted >= opt.hold_goals) {
        released = true;
        pthread_cond_broadcast(&state_changed);
      }
      pthread_mutex_unlock(&state_lock);
    }
    pthread_attr_t attr;
    pthread_attr_init(&attr);
    pthread_attr_setstacksize(&attr, THREAD_STACK);
    g->has_thread = pthread_create(&g->thread, &attr, run_goal, g) == 0;
    pthread_attr_destroy(&attr);
    if (!g->has_thread) {
      fprintf(stderr, "action_server: no thread for a goal\n");
      finish(g, false);
    }
  }
  test_msgs__action__Fibonacci_SendGoal_Request__fini(&request);
}

static void take_cancel_request(server_t *s) {
  rmw_request_id_t header;
  rcl_action_cancel_request_t request;
  action_msgs__srv__CancelGoal_Request__init(&request);
  rcl_ret_t ret = rcl_action_take_cancel_request(&s->action_server, &header, &request);
  if (!taken(ret, "take_cancel_request")) return;
  s->cancel_requests++;
  rcl_action_cancel_response_t response = rcl_action_get_zero_initialized_cancel_response();
  if (ok(rcl_action_process_cancel_request(&s->action_server, &request, &response),
         "process_cancel_request")) {
    for (size_t i = 0; i < response.msg.goals_canceling.size; i++) {
      goal_t *g = find_goal(s, response.msg.goals_canceling.data[i].goal_id.uuid);
      if (g != NULL && g->handle != NULL)
        ok(rcl_action_update_goal_state(g->handle, GOAL_EVENT_CANCEL_GOAL), "update_goal_state");
    }
    ok(rcl_action_send_cancel_response(&s->action_server, &header, &response.msg),
       "send_cancel_response");
    publish_status(s);
    ok(rcl_action_cancel_response_fini(&response), "cancel_response_fini");
  }
  action_msgs__srv__CancelGoal_Request__fini(&request);
}

static void take_result_request(server_t *s) {
  rmw_request_id_t header;
  result_request_t request;
  test_msgs__action__Fibonacci_GetResult_Request__init(&request);
  rcl_ret_t ret = rcl_action_take_result_request(&s->action_server, &header, &request);
  if (!taken(ret, "take_result_request")) return;
  s->result_requests++;
  goal_t *g = find_goal(s, request.goal_id.uuid);
  if (g == NULL) {
    send_result(s, &header, action_msgs__msg__GoalStatus__STATUS_UNKNOWN, 0);
  } else if (g->handle == NULL) {
    send_result(s, &header, g->status, g->published);
  } else {
    if (g->n_waiting == g->cap_waiting) {
      g->cap_waiting = g->cap_waiting * 2 + 2;
      g->waiting = realloc(g->waiting, g->cap_waiting * sizeof *g->waiting);
      if (g->waiting == NULL) abort();
    }
    g->waiting[g->n_waiting++] = header;
  }
  test_msgs__action__Fibonacci_GetResult_Request__fini(&request);
}

static void expire_goals(server_t *s) {
  rcl_action_goal_info_t expired[16];
  size_t n = 0;
  do {
    if (!ok(rcl_action_expire_goals(&s->action_server, expired, 16, &n), "expire_goals")) return;
    for (size_t i = 0; i < n; i++) {  // forgotten, as rcl_action forgot them
      for (goal_t **at = &s->goals; *at != NULL; at = &(*at)->next) {
        if (memcmp((*at)->uuid, expired[i].goal_id.uuid, 16) == 0 && (*at)->handle == NULL) {
          goal_t *gone = *at;
          *at = gone->next;
          // Terminal: its thread has left this server's calls and ends without the mutex.
          if (gone->has_thread) pthread_join(gone->thread, NULL);
          free(gone->waiting);
          free(gone);
          break;
        }
      }
    }
  } while (n == 16);
}

static void *run_executor(void *arg) {
  server_t *s = arg;
  while (running) {
    pthread_mutex_lock(&s->mutex);
    bool added = ok(rcl_wait_set_clear(&s->wait_set), "wait_set_clear") &&
                 ok(rcl_action_wait_set_add_action_server(&s->wait_set, &s->action_server, NULL),
                    "wait_set_add_action_server") &&
                 ok(rcl_wait_set_add_guard_condition(&s->wait_set, &s->wake, NULL),
                    "wait_set_add_guard_condition");
    pthread_mutex_unlock(&s->mutex);
    if (!added) break;
    rcl_ret_t ret = rcl_wait(&s->wait_set, RCL_S_TO_NS(1));
    if (ret == RCL_RET_TIMEOUT) continue;
    if (!ok(ret, "wait")) break;
    if (!running) break;
    pthread_mutex_lock(&s->mutex);
    bool goal = false, cancel = false, result = false, expired = false;
    if (ok(rcl_action_server_wait_set_get_entities_ready(&s->wait_set, &s->action_server, &goal,
                                                         &cancel, &result, &expired),
           "server_wait_set_get_entities_ready")) {
      if (goal) take_goal_request(s);
      if (cancel) take_cancel_request(s);
      if (result) take_result_request(s);
      if (expired) expire_goals(s);
    }
    pthread_mutex_unlock(&s->mutex);
  }
  return NULL;
}

// ---- set-up, commands and the end ---------------------------------------------------------------
static rmw_qos_profile_t queue(rmw_qos_profile_t profile, const char *depth) {
  profile.reliability = RMW_QOS_POLICY_RELIABILITY_RELIABLE;
  if (strcmp(depth, "all") == 0) {
    profile.history = RMW_QOS_POLICY_HISTORY_KEEP_ALL;
    profile.depth = 1000;
  } else {
    profile.history = RMW_QOS_POLICY_HISTORY_KEEP_LAST;
    profile.depth = (size_t)atoi(depth);
  }
  return profile;
}

static void start_server(server_t *s, int index) {
  s->index = index;
  if (opt.servers == 1) snprintf(s->action, sizeof s->action, "%s", opt.action);
  else snprintf(s->action, sizeof s->action, "%s_%d", opt.action, index);
  pthread_mutexattr_t attr;
  pthread_mutexattr_init(&attr);
  pthread_mutexattr_settype(&attr, PTHREAD_MUTEX_RECURSIVE);
  pthread_mutex_init(&s->mutex, &attr);
  pthread_mutexattr_destroy(&attr);
  rcl_allocator_t allocator = rcl_get_default_allocator();
  char name[64];
  snprintf(name, sizeof name, "cft_c_server_%d_%d", (int)getpid(), index);
  s->node = rcl_get_zero_initialized_node();
  rcl_node_options_t node_options = rcl_node_get_default_options();
  check(rcl_node_init(&s->node, name, "", &context, &node_options), "node_init");
  check(rcl_clock_init(RCL_SYSTEM_TIME, &s->clock, &allocator), "clock_init");
  rcl_action_server_options_t options = rcl_action_server_get_default_options();
  if (opt.depth != NULL) {
    options.goal_service_qos = queue(options.goal_service_qos, opt.depth);
    options.cancel_service_qos = queue(options.cancel_service_qos, opt.depth);
    options.result_service_qos = queue(options.result_service_qos, opt.depth);
    options.feedback_topic_qos = queue(options.feedback_topic_qos, opt.depth);
  }
  if (opt.feedback_depth > 0) {
    char depth[32];
    snprintf(depth, sizeof depth, "%d", opt.feedback_depth);
    options.feedback_topic_qos = queue(options.feedback_topic_qos, depth);
  }
  options.result_timeout.nanoseconds = (rcl_duration_value_t)(opt.result_timeout * 1e9);
  s->action_server = rcl_action_get_zero_initialized_server();
  check(rcl_action_server_init(&s->action_server, &s->node, &s->clock,
                               ROSIDL_GET_ACTION_TYPE_SUPPORT(test_msgs, Fibonacci), s->action,
                               &options),
        "action_server_init");
  s->wake = rcl_get_zero_initialized_guard_condition();
  check(rcl_guard_condition_init(&s->wake, &context, rcl_guard_condition_get_default_options()),
        "guard_condition_init");
  size_t subscriptions, guard_conditions, timers, clients, services;
  check(rcl_action_server_wait_set_get_num_entities(&s->action_server, &subscriptions,
                                                    &guard_conditions, &timers, &clients,
                                                    &services),
        "server_wait_set_get_num_entities");
  s->wait_set = rcl_get_zero_initialized_wait_set();
  check(rcl_wait_set_init(&s->wait_set, subscriptions, guard_conditions + 1, timers, clients,
                          services, 0, &context, allocator),
        "wait_set_init");
  if (pthread_create(&s->executor, NULL, run_executor, s) != 0) die("executor thread");
}

static void print_stats(void) {
  buf_t b = {0};
  struct rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  struct timespec now;
  clock_gettime(CLOCK_MONOTONIC, &now);
  static const char *const names[] = {
      "published", "accepted", "active", "peak_active", "rejected", "goal_requests",
      "goal_responses", "goal_response_errors", "result_requests", "result_responses",
      "result_response_errors", "cancel_requests", "late_ticks", "publish_errors"};
  enum { N = sizeof names / sizeof names[0] };
  unsigned long totals[N] = {0}, each[N];
  put(&b, "STATS {\"t\":%.6f,\"servers\":[", (double)now.tv_sec + (double)now.tv_nsec * 1e-9);
  for (int i = 0; i < opt.servers; i++) {
    server_t *s = &servers[i];
    pthread_mutex_lock(&s->mutex);
    unsigned long values[N] = {s->published, s->accepted, s->active, s->peak_active, s->rejected,
                               s->goal_requests, s->goal_responses, s->goal_response_errors,
                               s->result_requests, s->result_responses,
                               s->result_response_errors, s->cancel_requests, s->late_ticks,
                               s->publish_errors};
    pthread_mutex_unlock(&s->mutex);
    memcpy(each, values, sizeof each);
    put(&b, "%s{\"action\":", i ? "," : "");
    put_json_string(&b, s->action);
    for (int k = 0; k < N; k++) {
      put(&b, ",\"%s\":%lu", names[k], each[k]);
      totals[k] += each[k];
    }
    put(&b, "}");
  }
  put(&b, "]");
  for (int k = 0; k < N; k++) put(&b, ",\"%s\":%lu", names[k], totals[k]);
  pthread_mutex_lock(&state_lock);
  bool are_released = released || opt.hold_goals == 0;
  pthread_mutex_unlock(&state_lock);
  put(&b, ",\"held_accepted\":%d,\"released\":%s", held_accepted, are_released ? "true" : "false");
  put(&b, ",\"cpu_s\":%.6f,\"maxrss_kb\":%ld,\"uptime_s\":%.6f,",
      (double)usage.ru_utime.tv_sec + (double)usage.ru_utime.tv_usec * 1e-6 +
          (double)usage.ru_stime.tv_sec + (double)usage.ru_stime.tv_usec * 1e-6,
      usage.ru_maxrss, seconds_since(&started));
  put(&b, "\"switches\":%ld,\"preempted\":%ld,", usage.ru_nvcsw, usage.ru_nivcsw);
  put_guard(&b);
  put(&b, "}");
  emit(&b);
}

static void print_goals(void) {
  buf_t b = {0};
  put(&b, "GOALS {");
  bool first = true;
  for (int i = 0; i < opt.servers; i++) {
    server_t *s = &servers[i];
    pthread_mutex_lock(&s->mutex);
    for (goal_t *g = s->goals; g != NULL; g = g->next) {
      put(&b, first ? "" : ",");
      put_uuid(&b, g->uuid);
      put(&b, ":%d", g->published);
      first = false;
    }
    pthread_mutex_unlock(&s->mutex);
  }
  put(&b, "}");
  emit(&b);
}

static void stop_server(server_t *s) {
  ok(rcl_trigger_guard_condition(&s->wake), "trigger_guard_condition");
  pthread_join(s->executor, NULL);
}

static void fini_server(server_t *s) {
  for (goal_t *g = s->goals, *next; g != NULL; g = next) {
    next = g->next;
    free(g->waiting);
    free(g);
  }
  ok(rcl_wait_set_fini(&s->wait_set), "wait_set_fini");
  ok(rcl_guard_condition_fini(&s->wake), "guard_condition_fini");
  ok(rcl_action_server_fini(&s->action_server, &s->node), "action_server_fini");
  ok(rcl_clock_fini(&s->clock), "clock_fini");
  ok(rcl_node_fini(&s->node), "node_fini");
}

static void usage_error(const char *why) {
  fprintf(stderr, "action_server: %s\nusage: action_server ACTION PERIOD_S [--servers K] "
                  "[--pad N] [--depth N|all] [--feedback-depth N] [--result-timeout S] "
                  "[--hold-goals N]\n", why);
  exit(2);
}

static void parse(int argc, char **argv) {
  if (argc < 3) usage_error("ACTION and PERIOD_S are required");
  opt.action = argv[1];
  opt.period = atof(argv[2]);
  if (!(opt.period > 0)) usage_error("PERIOD_S must be positive");
  for (int i = 3; i < argc; i += 2) {
    if (i + 1 >= argc) usage_error("an option without its value");
    const char *name = argv[i], *value = argv[i + 1];
    if (strcmp(name, "--servers") == 0) opt.servers = atoi(value);
    else if (strcmp(name, "--pad") == 0) opt.pad = atoi(value);
    else if (strcmp(name, "--depth") == 0) opt.depth = value;
    else if (strcmp(name, "--feedback-depth") == 0) opt.feedback_depth = atoi(value);
    else if (strcmp(name, "--result-timeout") == 0) opt.result_timeout = atof(value);
    else if (strcmp(name, "--hold-goals") == 0) opt.hold_goals = atoi(value);
    else usage_error(name);
  }
  if (opt.servers < 1 || opt.pad < 0 || opt.hold_goals < 0) usage_error("a negative count");
}

int main(int argc, char **argv) {
  parse(argc, argv);
  clock_gettime(CLOCK_MONOTONIC, &started);
  released = opt.hold_goals == 0;
  pthread_condattr_t cond_attr;
  pthread_condattr_init(&cond_attr);
  pthread_condattr_setclock(&cond_attr, CLOCK_MONOTONIC);
  pthread_cond_init(&state_changed, &cond_attr);
  pthread_condattr_destroy(&cond_attr);

  rcl_allocator_t allocator = rcl_get_default_allocator();
  rcl_init_options_t init_options = rcl_get_zero_initialized_init_options();
  check(rcl_init_options_init(&init_options, allocator), "init_options_init");
  context = rcl_get_zero_initialized_context();
  check(rcl_init(0, NULL, &init_options, &context), "init");
  check(rcl_init_options_fini(&init_options), "init_options_fini");

  servers = calloc((size_t)opt.servers, sizeof *servers);
  for (int i = 0; i < opt.servers; i++) start_server(&servers[i], i);

  buf_t b = {0};
  put(&b, "ACTIONS [");
  for (int i = 0; i < opt.servers; i++) {
    put(&b, i ? "," : "");
    put_json_string(&b, servers[i].action);
  }
  put(&b, "]");
  emit(&b);
  print_guard_status();
  printf("READY\n");
  fflush(stdout);

  char line[256];
  while (fgets(line, sizeof line, stdin) != NULL) {
    line[strcspn(line, "\r\n")] = '\0';
    if (strcmp(line, "stats") == 0) {
      print_stats();
    } else if (strcmp(line, "goals") == 0) {
      print_goals();
    } else if (strcmp(line, "release") == 0) {
      pthread_mutex_lock(&state_lock);
      released = true;
      pthread_cond_broadcast(&state_changed);
      pthread_mutex_unlock(&state_lock);
    }
  }

  // End of input: stop the goals' threads and the executors, then destroy every entity, so that the
  // participant leaves the domain (and its shared-memory ports) cleanly.
  pthread_mutex_lock(&state_lock);
  running = false;
  pthread_cond_broadcast(&state_changed);
  pthread_mutex_unlock(&state_lock);
  for (int i = 0; i < opt.servers; i++) stop_server(&servers[i]);
  for (int i = 0; i < opt.servers; i++) {
    for (goal_t *g = servers[i].goals; g != NULL; g = g->next)
      if (g->has_thread) pthread_join(g->thread, NULL);
  }
  for (int i = 0; i < opt.servers; i++) fini_server(&servers[i]);
  free(servers);
  ok(rcl_shutdown(&context), "shutdown");
  ok(rcl_context_fini(&context), "context_fini");
  return 0;
}
