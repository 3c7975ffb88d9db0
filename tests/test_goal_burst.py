"""Issue 18: a burst of goals with a caller-supplied UUID in it loses no feedback.

The first feedback of goals sent just before a caller-supplied UUID was lost because the client,
inside that ``send_goal_async``, logged its one-time note through rclpy's logger, whose caller
lookup takes 50-165 ms on its first call in a process: nobody took feedback meanwhile, and the
feedback queue (keep-last, one history for all goals) replaced the oldest messages. The client's
logs now never go through that lookup (``PromptLogger``). The helper makes the lookup take seconds,
which makes the loss certain for a client that still uses it.
"""

import json

import pytest

from harness.ros import unique_name
from tests.support import action_server, helper_process

STALL_S = 3.0
# 7 goals x 4 Hz: the helper's queue of 40 holds 1.4 s of feedback, while the 6 goals sent before
# the stall publish all their 60 messages within it. A queue of 0.28 s (20 at 10 Hz) once lost one
# message in CI with no stall of the client's own: a shared machine can pause a process that long.
PERIOD = 0.25


@pytest.mark.parametrize('mode', ['client', 'goals'])
def test_goals_sent_before_a_caller_uuid_keep_their_first_feedback(mode):
    action = '/' + unique_name('fib')
    server = action_server(action, PERIOD)
    try:
        client = helper_process('tests.helpers.burst_client', [action, mode, STALL_S], ready='')
        try:
            report = json.loads(client.expect('RESULT', timeout=120).split(' ', 1)[1])
        finally:
            client.stop()
        assert server.poll() is None, f'server died\n{server.tail()}'
    finally:
        server.stop()
    timing = report.pop('timing')
    answered = {key: goal['feedback'] for key, goal in report.items() if goal['answered']}
    assert answered, report
    for key, feedback in answered.items():
        assert feedback == list(range(10)), (key, timing, report)
