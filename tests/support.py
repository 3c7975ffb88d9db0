"""Shared test machinery: a ROS session in the test process, and child processes in their own."""

from __future__ import annotations

import os
import queue
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path
from typing import Callable, Optional, Sequence

import rclpy
from rclpy.context import Context
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node

HELPERS = Path(__file__).parent / 'helpers'


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


class ChildProcess:
    """A helper script in its own Python process, driven by lines on stdin and stdout."""

    def __init__(self, script: str, args: Sequence[str] = (), *,
                 env: Optional[dict] = None, ready: str = 'READY', timeout: float = 30.0) -> None:
        command = [sys.executable, '-u', str(HELPERS / script), *map(str, args)]
        self.lines: queue.Queue[str] = queue.Queue()
        self.stderr_lines: list[str] = []
        self.proc = subprocess.Popen(
            command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True, env=env or os.environ.copy(), start_new_session=True)
        threading.Thread(target=self._pump, args=(self.proc.stdout, self.lines.put),
                         daemon=True).start()
        threading.Thread(target=self._pump, args=(self.proc.stderr, self.stderr_lines.append),
                         daemon=True).start()
        if ready:
            self.expect(ready, timeout)

    @staticmethod
    def _pump(stream, sink) -> None:
        for line in stream:
            sink(line.rstrip('\n'))

    def expect(self, prefix: str, timeout: float) -> str:
        """Return the next stdout line starting with ``prefix``; fail after ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f'no {prefix!r} from {self.proc.args[2]} within {timeout} s; '
                                   f'exit={self.proc.poll()} stderr={self.stderr_lines[-10:]}')
            try:
                line = self.lines.get(timeout=min(remaining, 0.2))
            except queue.Empty:
                continue
            if line.startswith(prefix):
                return line

    def send(self, line: str) -> None:
        self.proc.stdin.write(line + '\n')
        self.proc.stdin.flush()

    def request(self, line: str, reply: str, timeout: float = 30.0) -> str:
        """Send a command line and return its reply line."""
        self.send(line)
        return self.expect(reply, timeout)

    def stop(self, timeout: float = 10.0) -> Optional[int]:
        """Stop the process: close stdin, then SIGTERM, then SIGKILL; return its exit code."""
        if self.proc.poll() is None:
            try:
                self.proc.stdin.close()
            except OSError:
                pass
            try:
                self.proc.wait(timeout=timeout / 2)
            except subprocess.TimeoutExpired:
                self.proc.terminate()
                try:
                    self.proc.wait(timeout=timeout / 2)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait(timeout=timeout)
        return self.proc.returncode
