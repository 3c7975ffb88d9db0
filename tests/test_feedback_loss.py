"""Feedback that a stalled client loses, and how much its feedback queue keeps.

rmw_fastrtps destroys and recreates the feedback DataReader when the first content filter is set.
These tests pin that the recreated reader keeps the history the caller asked for: when the
executor does not take feedback for a while, the reader keeps the newest ``depth`` messages, as a
plain rclpy client does, and a deeper ``feedback_sub_qos_profile`` keeps them all.
"""

import time

import pytest
from rclpy.qos import QoSProfile

from cft_action import guard
from harness.ros import unique_name
from tests.support import action_server, result_of, send
from tests.test_action_client import PERIOD, make_client

ORDER = 30   # feedback messages of the one goal: three times rclpy's default depth of 10
DEFAULT_DEPTH = 10


def stalled_goal_feedback(ros, client, child):
    """Send one goal, then take nothing until the server has published all its feedback."""
    received = []
    published = child.request_json('stats', 'STATS')['published']  # make_client's proof's goals
    goal_handle = send(ros, client, ORDER,
                       feedback_callback=lambda msg: received.append(msg.feedback.sequence[0]))
    deadline = time.monotonic() + 30
    while child.request_json('stats', 'STATS')['published'] - published < ORDER:
        assert time.monotonic() < deadline, 'the server did not publish the feedback in 30 s'
        time.sleep(0.1)
    time.sleep(0.5)  # the last samples travel to the reader; the executor still does not run
    assert list(result_of(ros, goal_handle).result.sequence) == [ORDER]
    ros.spin_until(lambda: received and received[-1] == ORDER - 1, 10)
    ros.spin_for(0.5)
    return received


@pytest.mark.parametrize('depth', [None, 1000])
@pytest.mark.parametrize('mode', ['client', 'goals', 'off'])
def test_a_stalled_client_keeps_the_newest_feedback_its_queue_depth_holds(ros, mode, depth):
    action = '/' + unique_name('fib')
    child = action_server(action, PERIOD, env=guard.environment())
    try:
        kwargs = {} if depth is None else {'feedback_sub_qos_profile': QoSProfile(depth=depth)}
        client = make_client(ros, action, feedback_filter=mode, **kwargs)
        received = stalled_goal_feedback(ros, client, child)
        assert client.feedback_filter_state.active == (mode != 'off')
        if depth is None:
            # Keep-last 10, as rclpy: the oldest messages were replaced while nobody took them.
            assert set(range(ORDER - DEFAULT_DEPTH, ORDER)) <= set(received), received
            assert len(received) < ORDER, received
        else:
            assert received == list(range(ORDER)), received
        assert child.poll() is None, f'server died\n{child.tail()}'
    finally:
        child.stop()
