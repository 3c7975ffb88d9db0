"""A client node written the way real nodes are: coroutine timer callbacks, one reentrant callback
group for the timer and the action client, a 4-thread ``MultiThreadedExecutor``.

Usage: ``python -m tests.helpers.coroutine_client ACTION MODE GOALS IN_FLIGHT DEADLINE_S [DEPTH]``

``MODE`` is a ``feedback_filter`` mode of cft_action, or ``rclpy`` for plain rclpy's client. The
timer's callback is a coroutine that, while fewer than ``IN_FLIGHT`` goals run and fewer than
``GOALS`` were sent, awaits ``send_goal_async`` (with a feedback callback) and then
``get_result_async``. It spins until every goal has its result or ``DEADLINE_S`` passed, then
prints ``RESULT <json>``: goals sent, results, the feedback received per goal against what the
server published (the result's ``sequence[0]``), and feedback of other goals. An exception that
ends the spin is printed as ``SPIN_ERROR <repr>``, and the process exits with status 3.

``DEPTH`` makes the goal and result services' queues keep-last ``DEPTH`` (default: rclpy's 10).
Every client's response reader receives the responses to all clients, so at rclpy's depth a client
that lags behind the others loses its own responses, and their goals never complete, plain rclpy's
as much as cft_action's (README, "Differences from rclpy", the row on goal service queues).
"""

import json
import sys
import time
import traceback
import uuid
from typing import Optional

import rclpy
from rclpy.action import ActionClient as RclpyActionClient
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from test_msgs.action import Fibonacci

from cft_action import ActionClient


class CoroutineClient(Node):

    def __init__(self, action: str, mode: str, goals: int, in_flight: int,
                 depth: Optional[int]) -> None:
        super().__init__(f'cft_coroutine_client_{uuid.uuid4().hex[:8]}')
        group = ReentrantCallbackGroup()
        queues = {} if depth is None else {f'{service}_service_qos_profile': QoSProfile(depth=depth)
                                           for service in ('goal', 'result')}
        if mode == 'rclpy':
            self.client = RclpyActionClient(self, Fibonacci, action, callback_group=group, **queues)
        else:
            self.client = ActionClient(self, Fibonacci, action, callback_group=group,
                                       feedback_filter=mode, **queues)
        self.goals, self.in_flight_max = goals, in_flight
        self.sent = self.running = 0
        self.feedback: dict[int, int] = {}  # goal index -> feedback messages received
        self.foreign = 0
        self.published: dict[int, int] = {}  # goal index -> feedback the server published
        self.stage: dict[int, str] = {}  # goal index -> what it awaits: 'response' or 'result'
        self.handles: dict[int, object] = {}  # goal index -> its handle, while it awaits the result
        self.timer = self.create_timer(0.02, self.tick, callback_group=group)

    async def tick(self) -> None:
        if self.sent >= self.goals or self.running >= self.in_flight_max:
            return
        index = self.sent
        self.sent += 1
        self.running += 1
        self.feedback[index] = 0
        goal_uuid: list[bytes] = []

        def on_feedback(message) -> None:
            if goal_uuid and bytes(message.goal_id.uuid) != goal_uuid[0]:
                self.foreign += 1
            self.feedback[index] += 1

        try:
            self.stage[index] = 'response'
            goal_handle = await self.client.send_goal_async(Fibonacci.Goal(order=5), on_feedback)
            goal_uuid.append(bytes(goal_handle.goal_id.uuid))
            if goal_handle.accepted:
                self.stage[index] = 'result'
                self.handles[index] = goal_handle
                response = await goal_handle.get_result_async()
                self.published[index] = response.result.sequence[0]
            del self.stage[index]
        finally:
            self.running -= 1

    def done(self) -> bool:
        return len(self.published) >= self.goals


def main() -> None:
    action, mode = sys.argv[1], sys.argv[2]
    goals, in_flight, deadline_s = int(sys.argv[3]), int(sys.argv[4]), float(sys.argv[5])
    depth = int(sys.argv[6]) if len(sys.argv) > 6 else None
    rclpy.init()
    node = CoroutineClient(action, mode, goals, in_flight, depth)
    if not node.client.wait_for_server(timeout_sec=20):
        print('NO SERVER', flush=True)
        return
    print('READY', flush=True)
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    deadline = time.monotonic() + deadline_s
    status = 0
    try:
        while not node.done() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
    except Exception as error:  # noqa: BLE001 - what ends a user's spin is the finding
        print(f'SPIN_ERROR {error!r}', flush=True)
        traceback.print_exc()
        status = 3
    lost = {i: node.published[i] - node.feedback[i] for i in node.published
            if node.feedback[i] != node.published[i]}
    state = getattr(node.client, 'feedback_filter_state', None)
    print('RESULT ' + json.dumps({'sent': node.sent, 'results': len(node.published),
                                  'foreign': node.foreign, 'short_feedback': lost,
                                  'unfinished': node.stage,
                                  'unfinished_status': {i: node.handles[i].status
                                                        for i in node.stage if i in node.handles},
                                  'pending_results': len(node.client._pending_result_requests),
                                  'state': state._asdict() if state else None}), flush=True)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    sys.exit(status)


if __name__ == '__main__':
    main()
