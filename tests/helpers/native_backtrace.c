// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The test process's native backtrace when it dies of a signal, for failures that come once in
// many runs (a CI run of 3.12 segfaulted in rclpy's destroy_node once, and pytest's faulthandler
// showed only the Python frame). tests/conftest.py compiles and loads this at start-up.
//
// On SIGSEGV, SIGBUS, SIGFPE, SIGILL or SIGABRT the handler starts `timeout LIMIT gdb -p PID
// -batch -ex 'thread apply all bt'` on this process, writing to the stderr the suite started with,
// waits for it, then hands the signal to the handler it replaced (faulthandler's Python frames,
// then the default action). The crashed thread sits in this handler while gdb reads it, so its
// frames are those under "<signal handler called>". Everything the handler needs is prepared at
// install time: it calls only vfork, execv, waitpid, sigaction and raise, and vfork runs no
// atfork handlers, which would take malloc's locks (a crash inside malloc holds them).
#define _GNU_SOURCE
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

static const int fatal_signals[] = {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT};
#define FATAL_COUNT (sizeof fatal_signals / sizeof fatal_signals[0])
static struct sigaction previous[FATAL_COUNT];
static char timeout_path[512], limit[16], gdb_path[512], pid_text[16];
static char *argv[] = {timeout_path, limit, gdb_path, "-q", "-nx", "-batch", "-p", pid_text,
                       "-iex", "set auto-load off", "-ex", "set debuginfod enabled off",
                       "-ex", "thread apply all bt 40", NULL};
static int report_fd = 2;

static void on_fatal_signal(int signum) {
  static volatile sig_atomic_t reporting;
  if (!reporting) {
    reporting = 1;
    static const char banner[] = "\n=== native backtrace of the test process (gdb) ===\n";
    if (write(report_fd, banner, sizeof banner - 1) < 0) {}
    pid_t child = vfork();
    if (child == 0) {
      dup2(report_fd, 1);
      dup2(report_fd, 2);
      execv(timeout_path, argv);
      _exit(127);
    }
    if (child > 0) waitpid(child, NULL, 0);
  }
  for (size_t i = 0; i < FATAL_COUNT; i++)
    if (fatal_signals[i] == signum) sigaction(signum, &previous[i], NULL);
  raise(signum);
}

// Install for this process; 0 on success. fd: where to write (a copy of the suite's stderr).
int native_backtrace_install(const char *timeout, const char *gdb, int seconds, int fd) {
  if (snprintf(timeout_path, sizeof timeout_path, "%s", timeout) >= (int)sizeof timeout_path ||
      snprintf(gdb_path, sizeof gdb_path, "%s", gdb) >= (int)sizeof gdb_path)
    return -1;
  snprintf(limit, sizeof limit, "%d", seconds);
  snprintf(pid_text, sizeof pid_text, "%d", (int)getpid());
  report_fd = fd;
  prctl(PR_SET_PTRACER, PR_SET_PTRACER_ANY, 0, 0, 0);  // Yama: let the child gdb attach
  struct sigaction action;
  memset(&action, 0, sizeof action);
  action.sa_handler = on_fatal_signal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_NODEFER;  // the chained handler may raise the same signal again
  for (size_t i = 0; i < FATAL_COUNT; i++)
    if (sigaction(fatal_signals[i], &action, &previous[i]) != 0) return -1;
  return 0;
}
