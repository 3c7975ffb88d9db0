# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Processes for tests/test_guard.py: each role runs in its own process, started by the test.

    guard_scenario.py talker COUNT              publish COUNT std_msgs/String, report the guard
    guard_scenario.py listener EXPECT TIMEOUT   count std_msgs/String until EXPECT or TIMEOUT s
    guard_scenario.py server PERIOD DURATION    Fibonacci action server, feedback every PERIOD s
    guard_scenario.py goal DURATION             an ordinary client that keeps one goal running
    guard_scenario.py churn UPDATES INTERVAL SERVER_PID
                                                a client that changes its feedback filter
                                                UPDATES times, every INTERVAL s

Every wait is bounded. The action and topic names come from GUARD_ACTION and GUARD_TOPIC.
Lines the test reads start with a capitalised keyword (READY, STATUS, ...).
Content filters are set through the project's binding, :mod:`cft_action._rcl`.
"""

from __future__ import annotations

import os
import sys
import time

import rclpy
from rclpy.action import ActionClient, ActionServer
from rclpy.node import Node

ACTION = os.environ.get('GUARD_ACTION', 'guard_fib')
TOPIC = os.environ.get('GUARD_TOPIC', 'guard_chatter')
# Two expressions that match no goal: the churn toggles between them, so every update is a real
# change (an SEDP message the server's writer must process) and never the empty string.
NEVER = ('goal_id.uuid[0] = 0 AND goal_id.uuid[0] = 1',
         'goal_id.uuid[0] = 0 AND goal_id.uuid[0] = 2')


def say(*words: object) -> None:
    print(*words, flush=True)


def report_guard() -> None:
    import cft_action.guard as guard
    say('STATUS', guard.is_active(), guard.status())
    say('CALLS', ' '.join(f'{k}={v}' for k, v in guard.call_counts().items()))


def talker(count: int) -> int:
    from std_msgs.msg import String
    node = Node('guard_talker')
    pub = node.create_publisher(String, TOPIC, 10)
    deadline = time.monotonic() + 10.0
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    say('MATCHED', pub.get_subscription_count())
    for i in range(count):
        pub.publish(String(data=f'hello {i}'))
        rclpy.spin_once(node, timeout_sec=0.05)
    say('PUBLISHED', count)
    report_guard()
    return 0


def listener(expect: int, timeout: float) -> int:
    from std_msgs.msg import String
    node = Node('guard_listener')
    got = []
    node.create_subscription(String, TOPIC, lambda m: got.append(m.data), 10)
    say('READY')
    deadline = time.monotonic() + timeout
    while len(got) < expect and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    say('RECEIVED', len(got))
    return 0


def server(period: float, duration: float) -> int:
    from test_msgs.action import Fibonacci
    node = Node('guard_fib_server')

    def execute(goal_handle):
        say('GOAL')
        feedback = Fibonacci.Feedback()
        feedback.sequence = [0] * 100
        published = 0
        end = time.monotonic() + duration
        next_report = time.monotonic() + 1.0
        while time.monotonic() < end:
            goal_handle.publish_feedback(feedback)
            published += 1
            time.sleep(period)
            if time.monotonic() >= next_report:  # the test reads the last one
                report_guard()
                next_report += 1.0
        say('PUBLISHED', published)
        goal_handle.succeed()
        return Fibonacci.Result()

    ActionServer(node, Fibonacci, ACTION, execute)
    report_guard()
    say('READY')
    end = time.monotonic() + duration + 30.0
    while time.monotonic() < end:  # single-threaded executor, as in the reported crashes
        rclpy.spin_once(node, timeout_sec=0.1)
    return 0


def goal(duration: float) -> int:
    from test_msgs.action import Fibonacci
    node = Node('guard_goal')
    client = ActionClient(node, Fibonacci, ACTION)
    if not client.wait_for_server(timeout_sec=15.0):
        say('NO_SERVER')
        return 1
    received = [0]

    def on_feedback(_msg):
        received[0] += 1
        if received[0] == 1:
            say('FEEDBACK')

    future = client.send_goal_async(Fibonacci.Goal(order=1), feedback_callback=on_feedback)
    rclpy.spin_until_future_complete(node, future, timeout_sec=15.0)
    if not future.done() or not future.result().accepted:
        say('NOT_ACCEPTED')
        return 1
    say('ACCEPTED')
    end = time.monotonic() + duration
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
    say('RECEIVED', received[0])
    return 0


def _alive(pid: int) -> bool:
    """Whether ``pid`` still runs (a zombie, not yet reaped by the test, counts as dead)."""
    try:
        with open(f'/proc/{pid}/stat') as f:
            state = f.read().rsplit(')', 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ('Z', 'X')


def churn(updates: int, interval: float, server_pid: int) -> int:
    from test_msgs.action import Fibonacci
    from cft_action import _rcl
    node = Node('guard_churn')
    client = ActionClient(node, Fibonacci, ACTION)
    ptr, reason = _rcl.action_feedback_subscription(
        client._client_handle.pointer, node.resolve_topic_name(ACTION))
    if ptr is None:
        say('NO_FEEDBACK_SUBSCRIPTION', reason)
        return 2
    # The first filter recreates the reader: set it before the client is ever in a wait set.
    _rcl.set_content_filter(ptr, NEVER[0])
    if not client.wait_for_server(timeout_sec=15.0):
        say('NO_SERVER')
        return 1
    time.sleep(1.0)  # let discovery carry the first filter to the server
    say('CHURN_START')
    start = time.monotonic()
    for i in range(1, updates + 1):
        _rcl.set_content_filter(ptr, NEVER[i % 2])
        time.sleep(interval)
        if not _alive(server_pid):
            say('RESULT died_after', i, f'{time.monotonic() - start:.2f}s')
            return 0
    say('RESULT survived', updates, f'{time.monotonic() - start:.2f}s')
    return 0


def main(argv: list[str]) -> int:
    role, args = argv[0], argv[1:]
    rclpy.init()
    try:
        if role == 'talker':
            return talker(int(args[0]))
        if role == 'listener':
            return listener(int(args[0]), float(args[1]))
        if role == 'server':
            return server(float(args[0]), float(args[1]))
        if role == 'goal':
            return goal(float(args[0]))
        if role == 'churn':
            return churn(int(args[0]), float(args[1]), int(args[2]))
        raise SystemExit(f'unknown role {role!r}')
    finally:
        try:
            rclpy.try_shutdown()
        except Exception:  # noqa: BLE001 (best effort at exit)
            pass


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
