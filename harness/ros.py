"""A ROS session in this process: an rclpy context, one node and an executor."""

from __future__ import annotations

import time
import uuid
from typing import Callable

import rclpy
from rclpy.context import Context
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node


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
