"""A participant that tries to read an action's topics, for tests/test_sros2.py.

Usage: ``python -m tests.helpers.sros2_probe ACTION SECONDS``, in whatever security environment
the test gives it (an enclave whose permissions deny the action's topics, or none at all). It
tries a plain rclpy ActionClient and plain subscriptions to the action's feedback and status
topics, each created on its own (so that one refused does not hide another), prints ``READY``,
then on ``go`` counts what they take for SECONDS and prints ``RESULT <json>``: ``refused``, the
rcl error of each that could not be created; ``feedback`` and ``status``, the messages taken;
``server``, whether the ActionClient saw the server.
"""

import json
import sys
import time

import rclpy
from action_msgs.msg import GoalStatusArray
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from test_msgs.action import Fibonacci


def say(line: str) -> None:
    """``line`` on a line of its own, in one write: Fast DDS's log thread writes its refusals to
    the same stdout through its own buffer, and may have left a line unfinished."""
    sys.stdout.write(f'\n{line}\n')
    sys.stdout.flush()


def main() -> None:
    action, seconds = sys.argv[1], float(sys.argv[2])
    rclpy.init()
    node = Node('cft_sros2_probe')
    refused: dict[str, str] = {}
    taken = {'feedback': 0, 'status': 0}
    client = None
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    try:
        client = ActionClient(node, Fibonacci, action)
    except (RuntimeError, ValueError) as error:  # rclpy's RCLError; ActionClient's ValueError
        refused['action_client'] = f'{type(error).__name__}: {error}'
    for name, kind in (('feedback', Fibonacci.Impl.FeedbackMessage), ('status', GoalStatusArray)):
        try:
            node.create_subscription(kind, f'{action}/_action/{name}',
                                     lambda _, n=name: taken.__setitem__(n, taken[n] + 1), qos)
        except RuntimeError as error:
            refused[name] = f'{type(error).__name__}: {error}'
    say('READY')
    sys.stdin.readline()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    say('RESULT ' + json.dumps({'refused': refused, **taken,
                                'server': bool(client is not None and client.server_is_ready())}))
    sys.stdin.readline()
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
