# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Processes for tests/test_guard.py: each role runs in its own process, started by the test.

    python -m tests.helpers.guard_scenario talker COUNT
        publish COUNT std_msgs/String, report the guard
    python -m tests.helpers.guard_scenario listener EXPECT TIMEOUT
        count std_msgs/String until EXPECT or TIMEOUT s

Every wait is bounded. The topic name comes from GUARD_TOPIC. Lines the test reads start with a
capitalised keyword (READY, STATUS, ...). The churn scenario is :mod:`harness.hazard`'s.
"""

from __future__ import annotations

import os
import sys
import time

import rclpy
from rclpy.node import Node

from harness.proc import run_role

TOPIC = os.environ.get('GUARD_TOPIC', 'guard_chatter')


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


ROLES = {'talker': talker, 'listener': listener}


if __name__ == '__main__':
    sys.exit(run_role(sys.argv[1:], ROLES))
