"""A hostile client for tests/test_hostile.py: it reads the goal UUIDs off an action's status topic,
as any participant can, and sends a goal request with each UUID it has not seen before, as if the
goal were its own (the server rejects them: it has a goal with that UUID).

Usage: ``python -m tests.helpers.goal_thief ACTION``. Prints ``READY`` once the server is found;
the line ``report`` prints ``STOLEN <json>``: requests sent, and answered with accepted or
rejected.
"""

import json
import sys
import threading

import rclpy
from action_msgs.msg import GoalStatusArray
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from test_msgs.action import Fibonacci
from unique_identifier_msgs.msg import UUID


def main() -> None:
    action = sys.argv[1]
    rclpy.init()
    node = Node('cft_goal_thief')
    client = ActionClient(node, Fibonacci, action)
    seen: set[bytes] = set()
    futures = []
    lock = threading.Lock()

    def on_status(message: GoalStatusArray) -> None:
        for status in message.status_list:
            uuid = bytes(status.goal_info.goal_id.uuid)
            if uuid not in seen:
                seen.add(uuid)
                with lock:
                    futures.append(client.send_goal_async(Fibonacci.Goal(order=1),
                                                          goal_uuid=UUID(uuid=list(uuid))))

    node.create_subscription(GoalStatusArray, f'{action}/_action/status', on_status, 100)
    if not client.wait_for_server(timeout_sec=30):
        print('NO_SERVER', flush=True)
        return
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    print('READY', flush=True)
    for line in sys.stdin:
        if line.strip() == 'report':
            with lock:
                answered = [f.result() for f in futures if f.done()]
                report = {'sent': len(futures),
                          'accepted': sum(r.accepted for r in answered),
                          'rejected': sum(not r.accepted for r in answered)}
            print('STOLEN ' + json.dumps(report), flush=True)
    rclpy.try_shutdown()  # ends the executor's spin


if __name__ == '__main__':
    main()
