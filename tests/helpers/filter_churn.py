"""Changes a subscription's filter in a loop while samples arrive (for tests/test_reader_lock.py).

Usage: ``python -m tests.helpers.filter_churn TOPIC SECONDS``. Subscribes to ``TOPIC`` (Int32),
filtered, prints ``READY`` once a sample arrived, then sets a new filter expression as fast as it
can for SECONDS while spinning, and prints ``SURVIVED <json>`` with the changes made, the samples
received and the reader lock's counters. A crash of Fast DDS ends the process before that line.
"""

import json
import sys
import time

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Int32

from cft_action import _rcl, create_filtered_subscription, set_content_filter


def main() -> None:
    topic, seconds = sys.argv[1], float(sys.argv[2])
    rclpy.init()
    node = Node('cft_filter_churn')
    received = [0]
    subscription = create_filtered_subscription(
        node, Int32, topic, lambda _: received.__setitem__(0, received[0] + 1),
        QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE), 'data >= %0', ['0'])
    deadline = time.monotonic() + 30
    while not received[0] and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    settle = time.monotonic() + 2  # the writer filters for the reader by then
    while time.monotonic() < settle:
        rclpy.spin_once(node, timeout_sec=0.05)
    print('READY', flush=True)
    changes = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        # A new expression each time: Fast DDS builds a new filter and clears the old one.
        set_content_filter(subscription, f'data > {changes % 7} OR data = {changes}')
        changes += 1
        rclpy.spin_once(node, timeout_sec=0.001)
    evaluations, replacements = _rcl.reader_lock_counts()
    print('SURVIVED ' + json.dumps({'changes': changes, 'received': received[0],
                                    'evaluations': evaluations,
                                    'replacements': replacements}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
