"""A ROS session in this process: an rclpy context, one node and an executor; and how a helper
process whose executor spins in a thread of its own ends."""

from __future__ import annotations

import os
import sys
import threading
import time
import uuid
from typing import Callable, NoReturn, Optional, Sequence

import rclpy
from rclpy.context import Context
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node


def unique_name(prefix: str) -> str:
    """A topic or action name no other test of this session uses."""
    return f'{prefix}_{uuid.uuid4().hex[:8]}'


class RosSession:
    """An rclpy context with one node and a single-threaded executor.

    :param context: an initialised context to make the node in, which :meth:`close` leaves to its
        owner (one participant for several sessions); None: a context of the session's own.
    """

    def __init__(self, executor_class: type[Executor] = SingleThreadedExecutor, *,
                 context: Optional[Context] = None, **executor_args) -> None:
        self._own_context = context is None
        self.context = Context() if context is None else context
        if self._own_context:
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
        if self._own_context:
            rclpy.shutdown(context=self.context)


def leave_spinning_process(executor: Executor, threads: Sequence[threading.Thread],
                           destroy: Callable[[], None]) -> NoReturn:
    """End a process whose ``executor`` spins in one of ``threads``, without finalization.

    Shuts the executor down and joins every thread that calls into rclpy; only if all ended does
    it call ``destroy`` (its nodes and entities) and shut rclpy down, so that the participant
    leaves its shared-memory ports cleanly; then ``os._exit(0)``.

    Why: a daemon thread that re-enters Python during interpreter finalization is ended by
    pthread_exit, whose unwinding through rclpy's C++ frames calls std::terminate (SIGABRT,
    "terminate called without an active exception"). A process that aborts with its participant
    alive leaves Fast DDS's shared-memory ports to the other processes of the domain in a state in
    which deleting their own participant later crashed (SIGSEGV in
    SharedMemChannelResource::release, under rmw_destroy_node of a test's last node, twice on
    Python 3.12, after a parameter-node helper that ended so).
    """
    executor.shutdown(timeout_sec=2)
    for thread in threads:
        thread.join(2.0)
    if not any(thread.is_alive() for thread in threads):
        destroy()
        rclpy.try_shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)
