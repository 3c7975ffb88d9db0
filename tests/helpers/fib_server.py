"""A Fibonacci action server in its own process, publishing feedback from a ticker thread.

Usage: fib_server.py ACTION PERIOD_S [PAD]
Goal ``order`` is the number of feedback messages; feedback ``sequence`` is ``[k] + [0] * PAD``.
Execute callbacks are coroutines, so one single-threaded executor serves any number of goals
(rclpy's ActionServer dropped goal requests under a MultiThreadedExecutor here). The first
feedback of every goal is published in the first line of ``execute``; the ticker then
publishes one per goal every PERIOD_S. Goals with a negative order are rejected; cancels are
accepted. Commands on stdin: ``stats`` replies ``STATS <feedback published> <goals accepted>``.
"""

import sys
import threading
import time

import rclpy
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from test_msgs.action import Fibonacci


# rclpy's default depth of 10 drops requests when many clients send goals at once (measured: 4 of
# 15 goals lost with 3 clients), and any keep-last queue drops when a client on a loaded machine
# lags: these tests are about filtering, so every queue keeps all.
DEEP = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000,
                  reliability=ReliabilityPolicy.RELIABLE)
DEEP_QOS = {'goal_service_qos_profile': DEEP, 'result_service_qos_profile': DEEP,
            'cancel_service_qos_profile': DEEP, 'feedback_pub_qos_profile': DEEP}


class TickingServer:
    def __init__(self, node: Node, executor, action: str, period: float, pad: int) -> None:
        self.executor = executor
        self.period = period
        self.pad = [0] * pad
        self.lock = threading.Lock()
        self.active: dict = {}  # id(goal handle) -> [goal handle, next k, order, done future]
        self.published = 0
        self.accepted = 0
        ActionServer(node, Fibonacci, action, execute_callback=self.execute,
                     goal_callback=self.on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
                     callback_group=ReentrantCallbackGroup(), **DEEP_QOS)
        threading.Thread(target=self.tick, daemon=True).start()

    def on_goal(self, request) -> GoalResponse:
        return GoalResponse.REJECT if request.order < 0 else GoalResponse.ACCEPT

    def publish(self, goal_handle, k: int) -> None:
        goal_handle.publish_feedback(Fibonacci.Feedback(sequence=[k] + self.pad))
        with self.lock:
            self.published += 1

    async def execute(self, goal_handle):
        order = goal_handle.request.order
        if order > 0:
            self.publish(goal_handle, 0)
        done = Future()
        with self.lock:
            self.accepted += 1
            self.active[id(goal_handle)] = [goal_handle, 1, order, done]
        outcome = await done
        if outcome == 'canceled':
            goal_handle.canceled()
        else:
            goal_handle.succeed()
        return Fibonacci.Result(sequence=[order])

    def tick(self) -> None:
        while True:
            time.sleep(self.period)
            with self.lock:
                goals = list(self.active.items())
            finished = []
            for key, entry in goals:
                goal_handle, k, order, done = entry
                if goal_handle.is_cancel_requested:
                    finished.append((key, done, 'canceled'))
                elif k >= order:
                    finished.append((key, done, 'succeeded'))
                else:
                    self.publish(goal_handle, k)
                    entry[1] = k + 1
            with self.lock:
                for key, _, _ in finished:
                    del self.active[key]
            for _, done, outcome in finished:
                done.set_result(outcome)
            if finished:
                self.executor.wake()


def main() -> None:
    action, period = sys.argv[1], float(sys.argv[2])
    pad = int(sys.argv[3]) if len(sys.argv) > 3 else 0
    rclpy.init()
    node = Node('cft_test_server')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    server = TickingServer(node, executor, action, period, pad)
    threading.Thread(target=executor.spin, daemon=True).start()
    print('READY', flush=True)
    for line in sys.stdin:
        if line.strip() == 'stats':
            with server.lock:
                print(f'STATS {server.published} {server.accepted}', flush=True)

    executor.shutdown(timeout_sec=2)
    rclpy.shutdown()


if __name__ == '__main__':
    main()
