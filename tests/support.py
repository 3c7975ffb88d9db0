"""Shared test machinery: a ROS session in the test process, and child processes in their own."""

from __future__ import annotations

import os
import sys
import time
import uuid
from pathlib import Path
from typing import Callable, Optional, Sequence

import rclpy
from rclpy.context import Context
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node

from demos._proc import Proc

HELPERS = Path(__file__).parent / 'helpers'
SERVER = Path(__file__).parents[1] / 'demos' / '_server.py'


def unique_name(prefix: str) -> str:
    """A topic or action name no other test of this session uses."""
    return f'{prefix}_{uuid.uuid4().hex[:8]}'


class RosSession:
    """An rclpy context with one node and a single-threaded executor."""

    def __init__(self, executor_class: type[Executor] = SingleThreadedExecutor,
                 **executor_args) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node(unique_name('test_node'), context=self.context)
        self.executor = executor_class(context=self.context, **executor_args)
        self.executor.add_node(self.node)

    def spin_until(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Spin until ``predicate()`` holds or ``timeout`` seconds pass; return the predicate."""
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                return predicate()
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def spin_for(self, seconds: float) -> None:
        """Spin for a fixed time, for checks that nothing more arrives."""
        self.spin_until(lambda: False, seconds)

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=5)
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def helper_process(script: str, args: Sequence[object] = (), *, env: Optional[dict] = None,
                   ready: str = 'READY', timeout: float = 30.0) -> Proc:
    """A script of tests/helpers in its own Python process, driven by lines on stdin and stdout.

    Waits for its ``ready`` line (none if empty); the caller stops it.
    """
    argv = [sys.executable, '-u', str(HELPERS / script), *map(str, args)]
    return _started(Proc(script, argv, env or os.environ.copy()), ready, timeout)


def action_server(action: str, period: float, *, env: Optional[dict] = None,
                  late_feedback: float = 0.0, timeout: float = 30.0) -> Proc:
    """The project's Fibonacci action server (``demos/_server.py``) with keep-all queues.

    rclpy's default depth of 10 drops requests when many clients send goals at once (measured:
    4 of 15 goals lost with 3 clients), and any keep-last queue drops when a client on a loaded
    machine lags: these tests are about filtering, so every queue keeps all. ``late_feedback``:
    see the server's ``--late-feedback``.
    """
    argv = [sys.executable, '-u', str(SERVER), action, str(period), '--depth', 'all',
            '--late-feedback', str(late_feedback)]
    return _started(Proc('server', argv, env or os.environ.copy()), 'READY', timeout)


def _started(proc: Proc, ready: str, timeout: float) -> Proc:
    if ready:
        try:
            proc.expect(ready, timeout)
        except TimeoutError:
            proc.stop()
            raise
    return proc
