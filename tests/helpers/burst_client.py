"""The client of issue 18's scenario: a burst of goals sent before the first spin.

Usage: ``python -m tests.helpers.burst_client ACTION MODE STALL_S``

After ``wait_for_server`` and one goal whose feedback arrived
(:func:`tests.support.prove_feedback_path`, which proves that the server's feedback writer has
matched this client's reader: a server that discovers the reader late loses a goal's first
feedback for any client, plain rclpy's too), without spinning, it sends 6 goals
with generated UUIDs and a feedback callback, 1 with a caller-supplied random ``goal_uuid`` and a
feedback callback, and 1 without a feedback callback; then it spins until every answered goal
has its result and prints ``RESULT <json>``: per goal with a callback, the feedback indices
received, when each came, and whether it was answered; and the longest turns of the executor.
The feedback queue keeps the last 40 messages: more than a shared machine's pauses of this process
let pile up, fewer than the goals publish during STALL_S.

STALL_S makes every call of rclpy's logger caller lookup (``_find_caller``, which takes 50-165 ms
on its first call in a process) take that many seconds longer, so that a client that logs through
rclpy while it sends goals certainly stalls its executor past what the queue holds.
"""

import json
import sys
import time
import uuid

import rclpy
import rclpy.impl.rcutils_logger as rcutils_logger
from rclpy.node import Node
from rclpy.qos import QoSProfile
from test_msgs.action import Fibonacci
from unique_identifier_msgs.msg import UUID

from cft_action import ActionClient
from tests.support import connect_helper_client

DEPTH = 40
ORDER = 10


def slowed(stall_s):
    find_caller = rcutils_logger._find_caller

    def find_caller_slowly(frame):
        time.sleep(stall_s)
        return find_caller(frame)
    return find_caller_slowly


def main() -> None:
    action, mode, stall_s = sys.argv[1], sys.argv[2], float(sys.argv[3])
    rclpy.init()
    node = Node(f'cft_burst_client_{uuid.uuid4().hex[:8]}')
    client = ActionClient(node, Fibonacci, action, feedback_filter=mode,
                          feedback_sub_qos_profile=QoSProfile(depth=DEPTH))
    if not connect_helper_client(node, client):
        return
    rcutils_logger._find_caller = slowed(stall_s)
    received: dict[str, list[int]] = {}

    arrivals: dict[str, list[float]] = {}
    start = time.monotonic()

    def on_feedback(key):
        def record(msg) -> None:
            received[key].append(msg.feedback.sequence[0])
            arrivals[key].append(round(time.monotonic() - start, 3))
        return record

    sends = []
    for i in range(8):
        key = f'goal{i}'
        received[key] = []
        arrivals[key] = []
        goal_uuid = UUID(uuid=list(uuid.uuid4().bytes)) if i == 6 else None
        callback = on_feedback(key) if i < 7 else None
        sends.append((key, client.send_goal_async(Fibonacci.Goal(order=ORDER), callback,
                                                  goal_uuid)))
    sent = time.monotonic() - start
    deadline = time.monotonic() + 60
    results = {}
    spins = []  # (when, how long) of every spin_once: a long one is a stall of this executor
    while time.monotonic() < deadline:
        before = time.monotonic()
        rclpy.spin_once(node, timeout_sec=0.05)
        spins.append((round(before - start, 3), round(time.monotonic() - before, 3)))
        for key, future in sends:
            if future.done() and future.result().accepted and key not in results:
                results[key] = future.result().get_result_async()
        answered = [f for _, f in sends if f.done()]
        if len(answered) == len(sends) and all(r.done() for r in results.values()):
            break
    for _ in range(10):  # feedback still queued behind the results
        rclpy.spin_once(node, timeout_sec=0.05)
    report: dict = {key: {'answered': future.done() and future.result().accepted,
                          'feedback': received[key], 'arrivals': arrivals[key]}
                    for key, future in sends[:7]}
    # Evidence for a loss: how long the sends took, and the longest executor turns.
    report['timing'] = {'sent': round(sent, 3), 'filter': str(client.feedback_filter_state),
                        'longest_spins': sorted(spins, key=lambda spin: -spin[1])[:5]}
    print('RESULT ' + json.dumps(report), flush=True)


if __name__ == '__main__':
    main()
