"""Feedback queued while the executor was busy reaches the callbacks in one wake, in order, where
the client's callback group runs one callback at a time; one per wake in a reentrant group, as
rclpy (cft_action/action/_feedback_intake.py)."""

import time

import pytest
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.qos import QoSProfile
from test_msgs.action import Fibonacci

from cft_action import ActionClient
from cft_action.action._feedback_intake import FEEDBACK_BATCH
from harness.ros import unique_name
from tests.support import action_server, prove_feedback_path

ORDER = 30  # feedback messages of the goal, one every PERIOD
PERIOD = 0.01


@pytest.mark.parametrize('group', [MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup],
                         ids=['exclusive', 'reentrant'])
def test_queued_feedback_is_taken_in_one_wake_unless_the_group_is_reentrant(ros, group):
    action = '/' + unique_name('fib')
    server = action_server(action, PERIOD)
    try:
        client = ActionClient(ros.node, Fibonacci, action, callback_group=group(),
                              feedback_sub_qos_profile=QoSProfile(depth=100))
        assert client.wait_for_server(timeout_sec=20)
        prove_feedback_path(ros.spin_until, client)
        received: list[int] = []  # each message's index in its goal
        future = client.send_goal_async(Fibonacci.Goal(order=ORDER),
                                        lambda m: received.append(m.feedback.sequence[0]))
        assert ros.spin_until(future.done, 20) and future.result().accepted
        before = len(received)
        time.sleep(ORDER * PERIOD + 1.0)  # the executor is busy: the goal's feedback queues
        wakes = 0
        while len(received) < ORDER and wakes < 2 * ORDER:
            ros.executor.spin_once(timeout_sec=0.5)
            wakes += 1
        assert received == list(range(ORDER)), 'lost or out of order'
        queued = ORDER - before
        assert queued > 5, 'too little feedback was queued to tell'
        if group is ReentrantCallbackGroup:
            assert wakes >= queued  # one message a wake, as rclpy
        else:
            assert wakes <= 1 + queued // FEEDBACK_BATCH + 2  # plus a wake for status
        assert client.feedback_filter_state.feedback_taken >= ORDER
    finally:
        server.stop()
