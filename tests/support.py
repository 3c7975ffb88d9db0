"""Shared test machinery: the child processes of the tests, each in its own Python process.

A ROS session in the test process is :class:`harness.ros.RosSession`.
"""

from __future__ import annotations

import os
from typing import Optional, Sequence

from harness.proc import Proc, python_module


def helper_process(module: str, args: Sequence[object] = (), *, env: Optional[dict] = None,
                   ready: str = 'READY', timeout: float = 30.0) -> Proc:
    """A helper module (``tests.helpers.NAME``, ``harness.NAME``) in its own Python process.

    It is driven by lines on stdin and stdout. Waits for its ``ready`` line (none if empty); the
    caller stops it.
    """
    argv = python_module(module, *args)
    return _started(Proc(module, argv, env or os.environ.copy()), ready, timeout)


def action_server(action: str, period: float, *, env: Optional[dict] = None,
                  late_feedback: float = 0.0, timeout: float = 30.0) -> Proc:
    """The project's Fibonacci action server (:mod:`harness.server`) with keep-all queues.

    rclpy's default depth of 10 drops requests when many clients send goals at once (measured:
    4 of 15 goals lost with 3 clients), and any keep-last queue drops when a client on a loaded
    machine lags: these tests are about filtering, so every queue keeps all. ``late_feedback``:
    see the server's ``--late-feedback``.
    """
    argv = python_module('harness.server', action, period, '--depth', 'all',
                         '--late-feedback', late_feedback)
    return _started(Proc('server', argv, env or os.environ.copy()), 'READY', timeout)


def _started(proc: Proc, ready: str, timeout: float) -> Proc:
    if ready:
        try:
            proc.expect(ready, timeout)
        except TimeoutError:
            proc.stop()
            raise
    return proc
