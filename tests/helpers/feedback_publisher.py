"""Publishes action feedback messages with given goal UUIDs; used by the guard's filter tests.

Usage: ``python -m tests.helpers.feedback_publisher ACTION``: a plain publisher of the action's
FeedbackMessage type on ``ACTION/_action/feedback`` (what an rclpy ActionServer's feedback writer
is), reliable, keep all.
Commands on stdin, one per line:
  wait N          wait until exactly N subscriptions matched; replies MATCHED or TIMEOUT
  pub K UUIDHEX   publish feedback [K] for the goal UUID (32 hex digits); no reply
  stats           replies STATS <json>: the guard's filter counters and layout report
                  (guard.layout())
"""

import json
import sys

import rclpy
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from test_msgs.action import Fibonacci

from harness.polling import wait_until

from cft_action import guard


def main() -> None:
    rclpy.init()
    node = Node('cft_feedback_publisher')
    qos = QoSProfile(depth=1, history=HistoryPolicy.KEEP_ALL,
                     reliability=ReliabilityPolicy.RELIABLE)
    message_type = Fibonacci.Impl.FeedbackMessage
    publisher = node.create_publisher(message_type, f'{sys.argv[1]}/_action/feedback', qos)
    print('READY', flush=True)
    for line in sys.stdin:
        command, *arguments = line.split()
        if command == 'wait':
            wanted = int(arguments[0])
            matched = wait_until(lambda wanted=wanted: publisher.get_subscription_count() == wanted)
            print('MATCHED' if matched else 'TIMEOUT', flush=True)
        elif command == 'pub':
            message = message_type()
            message.goal_id.uuid = list(bytes.fromhex(arguments[1]))
            message.feedback.sequence = [int(arguments[0])]
            publisher.publish(message)
        elif command == 'stats':
            stats = {**guard.filter_counts(), 'layout': guard.layout()}
            print('STATS', json.dumps(stats), flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
