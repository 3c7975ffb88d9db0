# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Child processes driven by lines: the one process wrapper of the demos, benchmarks and tests.

Every helper process of this project speaks the same way: it prints lines that start with a
capitalised keyword (``READY``, ``STATS {...}``, ``RESULT ...``), reads commands from stdin, and
ends when stdin closes. :class:`Proc` starts one, collects its merged stdout and stderr on a
thread, and stops it for sure: every wait is bounded, and :meth:`Proc.stop` escalates to SIGKILL.
:func:`run_role` is the other side: the entry point of a script whose roles run as such processes.

A module of this repository runs in a child as ``python -m`` (:func:`python_module`): :class:`Proc`
puts the repository (:data:`ROOT`) first on every child's ``PYTHONPATH``, so the child imports
``harness``, ``demos``, ``benchmarks`` and ``tests`` whatever its working directory.
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import threading
import time
import typing
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Optional, Sequence

#: The repository: the directory that holds this package, ``demos``, ``benchmarks`` and ``tests``.
ROOT = Path(__file__).resolve().parents[1]


def python_module(module: str, *args: object) -> list[str]:
    """The command line ``python -u -m MODULE ARGS...`` with this interpreter.

    ``module`` is a dotted name under :data:`ROOT` (``harness.server``,
    ``tests.helpers.publisher``); a :class:`Proc` finds it through ``PYTHONPATH``.
    """
    return [sys.executable, '-u', '-m', module, *map(str, args)]


def pinned(cpus: Optional[str], argv: list[str]) -> list[str]:
    """``argv`` run on ``cpus`` only (``taskset -c`` syntax, e.g. ``'0'`` or ``'1-3'``), every
    thread it will start included; ``argv`` as it is where ``cpus`` is None."""
    return argv if cpus is None else ['taskset', '-c', cpus, *argv]


def add_cpu_arguments(parser: argparse.ArgumentParser) -> None:
    """A benchmark's ``--server-cpus`` and ``--client-cpus`` (for :func:`pinned`)."""
    parser.add_argument('--server-cpus', default=None, metavar='CPUS',
                        help='run the server on these CPUs only (taskset -c syntax, e.g. 0)')
    parser.add_argument('--client-cpus', default=None, metavar='CPUS',
                        help='run every client on these CPUs only (e.g. 1): with --server-cpus, '
                             'a client woken by a datagram cannot preempt the server, as when '
                             'the clients run on other machines')


def guard_command() -> list[str]:
    """``cft-action guard --``, from this interpreter's environment."""
    beside = Path(sys.executable).with_name('cft-action')
    found = str(beside) if beside.exists() else shutil.which('cft-action')
    if found:
        return [found, 'guard', '--']
    return [sys.executable, '-m', 'cft_action.cli', 'guard', '--']


def root_on_path(env: Mapping[str, str]) -> dict[str, str]:
    """``env`` with :data:`ROOT` first on ``PYTHONPATH`` (once)."""
    paths = [p for p in env.get('PYTHONPATH', '').split(os.pathsep) if p and p != str(ROOT)]
    return {**env, 'PYTHONPATH': os.pathsep.join([str(ROOT), *paths])}


class Proc:
    """A child process whose merged stdout and stderr are read line by line by a thread."""

    def __init__(self, name: str, argv: Sequence[str], env: dict[str, str], *,
                 cwd: Optional[str] = None, core: bool = False) -> None:
        """Start ``argv`` in a session of its own, with ``env`` and :data:`ROOT` on its path.

        :param name: what messages call it.
        :param core: allow a core dump (``RLIMIT_CORE`` unlimited), for a crash's backtrace.
        """
        self.name = name
        self.lines: list[str] = []
        self.cpu_lifetime_s: Optional[float] = None  # user + system seconds, once reaped
        self._cursor = 0  # where the next expect() starts
        self._closed = False
        self._changed = threading.Condition()

        def allow_core() -> None:
            resource.setrlimit(resource.RLIMIT_CORE,
                               (resource.RLIM_INFINITY, resource.RLIM_INFINITY))

        self.popen = subprocess.Popen(list(argv), env=root_on_path(env), cwd=cwd,
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True, errors='replace',
                                      start_new_session=True,
                                      preexec_fn=allow_core if core else None)
        self.pid = self.popen.pid
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            with self._changed:
                self.lines.append(line.rstrip('\n'))
                self._changed.notify_all()
        with self._changed:
            self._closed = True
            self._changed.notify_all()

    def wait_for(self, prefix: str, timeout: float, after: int = 0) -> Optional[str]:
        """The first line from index ``after`` on that starts with ``prefix``, or None.

        Waits at most ``timeout`` seconds, and not past the end of the process's output.
        """
        found = self._find(prefix, timeout, after)
        return None if found is None else self.lines[found]

    def _find(self, prefix: str, timeout: float, after: int) -> Optional[int]:
        deadline = time.monotonic() + timeout
        index = after
        with self._changed:
            while True:
                while index < len(self.lines):
                    if self.lines[index].startswith(prefix):
                        return index
                    index += 1
                remaining = deadline - time.monotonic()
                if self._closed or remaining <= 0:
                    return None
                self._changed.wait(remaining)

    def expect(self, prefix: str, timeout: float) -> str:
        """The next line, after the last one expected, that starts with ``prefix``.

        :raises TimeoutError: none came within ``timeout`` seconds; the message has the output.
        """
        found = self._find(prefix, timeout, self._cursor)
        if found is None:
            raise TimeoutError(f'{self.name}: no {prefix!r} within {timeout:g} s\n{self.tail()}')
        self._cursor = found + 1
        return self.lines[found]

    def all(self, prefix: str) -> list[str]:
        """Every line so far that starts with ``prefix``."""
        with self._changed:
            return [line for line in self.lines if line.startswith(prefix)]

    def last(self, prefix: str) -> Optional[str]:
        """The latest line so far that starts with ``prefix``, or None."""
        with self._changed:
            return next((line for line in reversed(self.lines) if line.startswith(prefix)), None)

    def send(self, line: str) -> None:
        """Write one command line; a process that is gone is not an error here."""
        try:
            assert self.popen.stdin is not None
            self.popen.stdin.write(line + '\n')
            self.popen.stdin.flush()
        except (OSError, ValueError):
            pass

    def request(self, command: str, reply: str, timeout: float = 30.0) -> str:
        """Send ``command`` and return the next line that starts with ``reply``."""
        self.send(command)
        return self.expect(reply, timeout)

    def request_json(self, command: str, reply: str, timeout: float = 30.0) -> dict[str, Any]:
        """Send ``command`` and parse the JSON after ``reply`` in the answer."""
        return json.loads(self.request(command, reply, timeout).split(' ', 1)[1])

    def close_stdin(self) -> None:
        """End the input: the helper processes take that as the request to finish."""
        try:
            if self.popen.stdin is not None:
                self.popen.stdin.close()
        except OSError:
            pass

    def wait(self, timeout: float) -> Optional[int]:
        """The exit status, or None if the process still runs after ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        while self.popen.returncode is None:
            try:
                pid, status, usage = os.wait4(self.pid, os.WNOHANG)
            except ChildProcessError:  # reaped elsewhere
                return self.popen.poll()
            if pid:
                self.popen.returncode = os.waitstatus_to_exitcode(status)
                self.cpu_lifetime_s = usage.ru_utime + usage.ru_stime
                break
            if time.monotonic() >= deadline:
                return None
            time.sleep(0.02)
        return self.popen.returncode

    def poll(self) -> Optional[int]:
        """The exit status, or None while it runs."""
        return self.wait(0)

    def stop(self, grace: float = 3.0) -> Optional[int]:
        """End the process and return its exit status.

        Closes stdin, then sends SIGINT, SIGTERM and SIGKILL, ``grace`` seconds apart.
        """
        self.close_stdin()
        steps = ((lambda: None, grace),
                 (lambda: self.popen.send_signal(signal.SIGINT), grace),
                 (self.popen.terminate, grace), (self.popen.kill, 10.0))
        for action, seconds in steps:
            if self.poll() is not None:
                break
            try:
                action()
            except ProcessLookupError:
                break
            self.wait(seconds)
        self._reader.join(5.0)
        return self.popen.returncode

    def tail(self, n: int = 30) -> str:
        """The last ``n`` lines, under a header with the name and exit status, for messages."""
        return f'--- {self.name} (rc={self.popen.returncode}) ---\n' + '\n'.join(self.lines[-n:])


def stop_all(processes: Iterable[Proc], grace: float = 3.0) -> list[Optional[int]]:
    """:meth:`Proc.stop` for each of ``processes``, their input closed all at once first, so that
    they finish together rather than one after another; their exit statuses, in order."""
    processes = list(processes)
    for process in processes:
        process.close_stdin()
    return [process.stop(grace) for process in processes]


def main_or_role(main: Callable[[list[str]], int], roles: dict[str, Callable[..., int]],
                 argv: Optional[Sequence[str]] = None) -> int:
    """The entry point of a script whose roles run as its own child processes.

    ``_role NAME ARGS...`` runs the role NAME of ``roles`` (:func:`run_role`); anything else is the
    script's command line, for ``main``. ``argv`` defaults to ``sys.argv[1:]``.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == '_role':
        return run_role(argv[1:], roles)
    return main(argv)


def run_role(argv: Sequence[str], roles: dict[str, Callable[..., int]]) -> int:
    """Run the role ``argv[0]`` with the arguments ``argv[1:]``, inside an rclpy context.

    Each argument is converted by the role function's type hint for its parameter (``str``,
    ``int``, ``float``). Returns the role's exit status; rclpy is shut down however it ends.
    """
    import rclpy
    name, args = argv[0], argv[1:]
    if name not in roles:
        raise SystemExit(f'unknown role {name!r}; roles: {", ".join(roles)}')
    role = roles[name]
    hints = typing.get_type_hints(role)
    values = [hints.get(param, str)(arg)
              for param, arg in zip(inspect.signature(role).parameters, args)]
    rclpy.init()
    try:
        return role(*values)
    finally:
        try:
            rclpy.try_shutdown()
        except Exception:  # noqa: BLE001 (best effort at exit)
            pass
