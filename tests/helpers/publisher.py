"""Publishes int, float and string samples on command; used by the filtered-subscription tests.

Usage: ``python -m tests.helpers.publisher PREFIX [DEPTH]``: reliable, keep-last DEPTH (default
1000). Commands on stdin, one per line:
  wait T N   wait until topic T (ints, floats or strings) has exactly N matched subscriptions,
             and still has after SETTLE seconds; replies MATCHED or TIMEOUT
  burst N [PERIOD]
             publish samples 0..N-1 on every topic, PERIOD seconds apart; replies SENT N
  flood S    publish ints 0, 1, ... as fast as it can for S seconds (a 1 ms pause every 50
             samples lets discovery run); replies SENT N
  steady HZ S BASE
             publish ints BASE, BASE + 1, ... at HZ for S seconds, on an absolute schedule;
             replies SENT N
  active T   replies ACTIVE A M: of the M matched subscriptions of topic T, A would take a
             message published now (cft_action.active_subscription_count)
  heartbeats replies HEARTBEATS {...}: cft_action.guard.heartbeat_counts() in this process
  programs replies PROGRAMS {...}: cft_action.guard.program_counts() in this process
"""

import json
import sys
import time

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64, Int32, String

from cft_action import active_subscription_count, guard
from harness.polling import TIMEOUT, wait_until

WORDS = ('hello', 'world', 'hello world')
#: A filtered subscription's first filter recreates its DataReader (rmw_fastrtps): the publisher
#: can count the reader that is about to go before it sees it go and the new one come, and a burst
#: sent then misses the new one (seen once in CI: a --content-filter echo got nothing). The count
#: must hold this long.
SETTLE = 0.3


def matched(publisher, wanted: int, timeout: float = TIMEOUT) -> bool:
    """Whether ``publisher`` has exactly ``wanted`` matched subscriptions, unchanged for
    ``SETTLE`` seconds, within ``timeout``."""
    deadline = time.monotonic() + timeout
    while wait_until(lambda: publisher.get_subscription_count() == wanted,
                     max(0.0, deadline - time.monotonic())):
        if not wait_until(lambda: publisher.get_subscription_count() != wanted, SETTLE):
            return True
    return False


def main() -> None:
    prefix = sys.argv[1]
    depth = int(sys.argv[2]) if len(sys.argv) > 2 else 1000
    qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
    rclpy.init()
    node = Node('cft_test_publisher')
    publishers = {
        'ints': (node.create_publisher(Int32, f'{prefix}/ints', qos), lambda i: Int32(data=i)),
        'floats': (node.create_publisher(Float64, f'{prefix}/floats', qos),
                   lambda i: Float64(data=i * 0.5)),
        'strings': (node.create_publisher(String, f'{prefix}/strings', qos),
                    lambda i: String(data=WORDS[i % len(WORDS)])),
    }
    print('READY', flush=True)
    for line in sys.stdin:
        command, _, argument = line.strip().partition(' ')
        if command == 'wait':
            topic, count = argument.split()
            print('MATCHED' if matched(publishers[topic][0], int(count)) else 'TIMEOUT',
                  flush=True)
        elif command == 'burst':
            count, _, period = argument.partition(' ')
            for i in range(int(count)):
                for publisher, make in publishers.values():
                    publisher.publish(make(i))
                if period:
                    time.sleep(float(period))
            print(f'SENT {count}', flush=True)
        elif command == 'active':
            publisher = publishers[argument][0]
            print(f'ACTIVE {active_subscription_count(publisher)} '
                  f'{publisher.get_subscription_count()}', flush=True)
        elif command == 'heartbeats':
            print(f'HEARTBEATS {json.dumps(guard.heartbeat_counts())}', flush=True)
        elif command == 'programs':
            print(f'PROGRAMS {json.dumps(guard.program_counts())}', flush=True)
        elif command == 'steady':
            hz, seconds, base = argument.split()
            publisher, make = publishers['ints']
            start, count = time.monotonic(), round(float(hz) * float(seconds))
            for i in range(count):
                time.sleep(max(0.0, start + i / float(hz) - time.monotonic()))
                publisher.publish(make(int(base) + i))
            print(f'SENT {count}', flush=True)
        elif command == 'flood':
            publisher, make = publishers['ints']
            end, sent = time.monotonic() + float(argument), 0
            while time.monotonic() < end:
                publisher.publish(make(sent))
                sent += 1
                if sent % 50 == 0:
                    time.sleep(0.001)
            print(f'SENT {sent}', flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
