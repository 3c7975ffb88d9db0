"""The load server: a Fibonacci action server whose feedback carries its publish time.

Usage: ``_server.py ACTION PERIOD_S PAD DEPTH``

Goal ``order`` is the number of feedback messages the goal gets; each feedback ``sequence`` is
``[k, seconds, nanoseconds] + [0] * PAD``, the publish time from ``time.time_ns()``, so that a
client on the same host can compute the latency from publish to its callback. The first feedback
of a goal is published in the first line of ``execute`` (as a real server that reports progress at
once), the others by a ticker thread every PERIOD_S, on an absolute schedule so that the rate stays
put when a tick takes long. Every queue is DEPTH deep (see :func:`_harness.queue_depth`).

Commands on stdin, one per line: ``stats`` replies ``STATS <json>`` with ``published`` (feedback
messages), ``accepted`` (goals), ``active`` (goals still running), ``late_ticks`` (ticks that
started more than a period late: the server could not keep the rate), ``intervals`` and
``interval_s`` (feedback intervals of finished goals and the seconds they took), ``cpu_s``
(user + system seconds of this process so far), ``guard`` (the server guard's status line) and
``writers`` (the GUIDs of the feedback and status writers, in hex). End of input stops the
server.

The same design as ``tests/helpers/fib_server.py``, which cannot be reused as is: its queue depth
is fixed, its feedback has no time stamp and its ticker drifts by the time a tick takes.
"""

from __future__ import annotations

import array
import json
import resource
import sys
import threading
import time
from typing import Any

import rclpy
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from test_msgs.action import Fibonacci

from cft_action import guard

#: Index of the first padding element in a feedback ``sequence``.
HEADER = 3

#: Seconds a finished goal stays on the server. Every status message lists all goals the server
#: keeps, and goes to every client: with rclpy's default of 900 s each phase of a run would carry
#: the goals of all earlier phases, and later configurations would receive more status bytes.
#: The load clients never ask for results, so nothing else depends on it.
RESULT_TIMEOUT_S = 2


class LoadServer:
    """Action server that publishes ``order`` time-stamped feedback messages per goal."""

    def __init__(self, node: Node, executor: SingleThreadedExecutor, action: str, period: float,
                 pad: int, depth: int) -> None:
        """Create the action server on ``node`` and start the ticker thread."""
        self.executor = executor
        self.period = period
        # A template copied per message: building a 2500-element list each time would cost the
        # server more CPU than the publish itself.
        self.template = array.array('i', [0] * (HEADER + pad))
        self.lock = threading.Lock()
        # id(goal handle) -> [goal handle, next k, order, done, first publish, last publish]
        self.active: dict[int, list[Any]] = {}
        self.published = 0
        self.accepted = 0
        self.late_ticks = 0
        # Over finished goals: feedback intervals, and the seconds they took (the achieved rate).
        self.intervals = 0
        self.interval_s = 0.0
        deep = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
        ActionServer(node, Fibonacci, action, execute_callback=self.execute,
                     goal_callback=self.on_goal,
                     cancel_callback=lambda _: CancelResponse.ACCEPT,
                     callback_group=ReentrantCallbackGroup(),
                     goal_service_qos_profile=deep, result_service_qos_profile=deep,
                     cancel_service_qos_profile=deep, feedback_pub_qos_profile=deep,
                     result_timeout=RESULT_TIMEOUT_S)
        threading.Thread(target=self.tick, daemon=True).start()

    def on_goal(self, request: Fibonacci.Goal) -> GoalResponse:
        """Accept every goal of non-negative order."""
        return GoalResponse.REJECT if request.order < 0 else GoalResponse.ACCEPT

    def publish(self, goal_handle: Any, k: int) -> None:
        """Publish feedback ``k`` of a goal, stamped with the current wall-clock time."""
        sequence = array.array('i', self.template)
        now = time.time_ns()
        sequence[0], sequence[1], sequence[2] = k, now // 1_000_000_000, now % 1_000_000_000
        goal_handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
        with self.lock:
            self.published += 1

    async def execute(self, goal_handle: Any) -> Fibonacci.Result:
        """Publish the first feedback at once; the ticker publishes the rest and ends the goal."""
        order = goal_handle.request.order
        first = time.monotonic()
        if order > 0:
            self.publish(goal_handle, 0)
        done = Future()
        with self.lock:
            self.accepted += 1
            self.active[id(goal_handle)] = [goal_handle, 1, order, done, first, first]
        outcome = await done
        if outcome == 'canceled':
            goal_handle.canceled()
        else:
            goal_handle.succeed()
        return Fibonacci.Result(sequence=[order])

    def tick(self) -> None:
        """Every period, publish the next feedback of each running goal, or finish the goal."""
        due = time.monotonic()
        while True:
            due += self.period
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -self.period:
                # Behind by more than a period: count it and restart the schedule rather than
                # publishing a burst of catch-up ticks, which would distort the latency.
                self.late_ticks += 1
                due = time.monotonic()
            with self.lock:
                goals = list(self.active.items())
            finished = []
            for key, entry in goals:
                goal_handle, k, order, done = entry[:4]
                if goal_handle.is_cancel_requested:
                    finished.append((key, done, 'canceled'))
                elif k >= order:
                    finished.append((key, done, 'succeeded'))
                else:
                    self.publish(goal_handle, k)
                    entry[1] = k + 1
                    entry[5] = time.monotonic()
            with self.lock:
                for key, _, _ in finished:
                    entry = self.active.pop(key)
                    self.intervals += max(0, entry[1] - 1)
                    self.interval_s += entry[5] - entry[4]
            for _, done, outcome in finished:
                done.set_result(outcome)
            if finished:
                self.executor.wake()

    def stats(self) -> dict[str, Any]:
        """Counters for the ``stats`` command."""
        usage = resource.getrusage(resource.RUSAGE_SELF)
        with self.lock:
            return {'published': self.published, 'accepted': self.accepted,
                    'active': len(self.active), 'late_ticks': self.late_ticks,
                    'intervals': self.intervals, 'interval_s': self.interval_s,
                    'cpu_s': usage.ru_utime + usage.ru_stime, 'guard': guard.status()}


def main() -> None:
    """Run the server until stdin closes."""
    action, period, pad, depth = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    rclpy.init()
    node = Node('cft_load_server')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    server = LoadServer(node, executor, action, period, pad, depth)
    # The RTPS GUIDs of the feedback and status writers, to tell their packets apart on the wire.
    writers = {name: [bytes(info.endpoint_gid).hex() for info in
                      node.get_publishers_info_by_topic(f'{action}/_action/{name}')]
               for name in ('feedback', 'status')}
    threading.Thread(target=executor.spin, daemon=True).start()
    print('READY', flush=True)
    for line in sys.stdin:
        if line.strip() == 'stats':
            print('STATS ' + json.dumps({**server.stats(), 'writers': writers}), flush=True)
    executor.shutdown(timeout_sec=2)
    rclpy.shutdown()


if __name__ == '__main__':
    main()
