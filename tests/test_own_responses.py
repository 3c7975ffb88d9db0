"""The response filter: an action client's goal, cancel and result response readers drop other
clients' responses in DDS's receive thread, so that they never wake its executor
(cft_action/native/reader/_response_filter.c), and the client's own responses still come."""

from __future__ import annotations

import pytest
from test_msgs.action import Fibonacci

from cft_action import _rcl, ActionClient
from cft_action.action.goal_filter import MODES
from harness.ros import unique_name
from tests.support import fastdds_header_probe, helper_process, round_trip
from tests.test_action_client import start_server
from tests.test_goal_status import server_done

#: Goals of the plain client in another process.
OTHERS_GOALS = 60
#: Its responses before it is ready: harness.client's round trip, one goal and its result.
ROUND_TRIP_RESPONSES = 2


@pytest.mark.parametrize('mode', MODES)
def test_other_clients_responses_are_dropped_before_the_executor(ros, mode):
    """A plain client in another process completes one goal and then sends 60 (it asks for no
    more results): each of their responses reaches this client's response readers, which drop
    it, and none reaches rmw's take. The client's own goals then still complete."""
    action = '/' + unique_name('fib')
    server = start_server(action, guarded=False, period=0.02)
    others = None
    try:
        client = ActionClient(ros.node, Fibonacci, action, feedback_filter=mode)
        state = client.response_filter_state
        assert state.active and state.reason == '', state
        assert client.wait_for_server(timeout_sec=20)
        assert round_trip(ros, client), 'the server never answered a goal'
        before = client.response_filter_state
        assert before.passed > 0 and before.dropped == 0, before
        others = helper_process('harness.client', [action, 'rclpy', OTHERS_GOALS, 2, 1000],
                                timeout=60)
        others.send('go')
        assert ros.spin_until(lambda: server_done(server, OTHERS_GOALS + 2), 60), server.tail()
        expected = OTHERS_GOALS + ROUND_TRIP_RESPONSES
        assert ros.spin_until(
            lambda: client.response_filter_state.dropped >= expected, 10), \
            client.response_filter_state
        ros.spin_for(0.5)
        after = client.response_filter_state
        assert (after.dropped, after.passed) == (expected, before.passed), after
        assert others.request_json('report', 'RESULT')['accepted'] == OTHERS_GOALS
        assert round_trip(ros, client), 'the client lost its own goal response'
        assert client.response_filter_state.passed > after.passed
        assert server.poll() is None, server.tail()
    finally:
        if others is not None:
            others.stop()
        server.stop()


def test_without_the_filter_the_client_works_as_rclpy_and_says_why(ros, monkeypatch):
    """Where the filter cannot be installed (a Fast DDS whose PLT or layout is not the one
    expected: produced here by replacing the installer's answer), the client says why in its
    state and its goals complete as with rclpy, whose take then drops others' responses."""
    monkeypatch.setattr(_rcl, 'response_filter_begin',
                        lambda: 'no free PLT slot in libfastrtps.so.2.14 for registerReader')
    action = '/' + unique_name('fib')
    server = start_server(action, guarded=False, period=0.02)
    try:
        client = ActionClient(ros.node, Fibonacci, action)
        state = client.response_filter_state
        assert not state.active and 'registerReader' in state.reason, state
        assert client.wait_for_server(timeout_sec=20)
        assert round_trip(ros, client), 'the server never answered a goal'
        assert client.response_filter_state[2:] == (0, 0)
    finally:
        server.stop()


READER_PROBE = '''
#define HAVE_SECURITY %d
#include <cstddef>
#include <cstdio>
#include <fastdds/rtps/reader/RTPSReader.h>
struct Probe : eprosima::fastrtps::rtps::RTPSReader {
  static void print() {
    std::printf("%%zu %%zu\\n", offsetof(Probe, mp_history), offsetof(Probe, data_filter_));
  }
};
int main() { Probe::print(); }
'''


def test_a_security_build_moves_the_readers_history_and_filter_alike(tmp_path):
    """The filter finds ``RTPSReader::data_filter_`` at the headers' offset moved by the distance
    at which the reader's history points back to it (cft_action/native/reader/_response_filter.c):
    Fast DDS's headers with and without ``HAVE_SECURITY`` (apt's build has it, the wheels' do not)
    move both members by the same distance, within the 64 bytes searched."""
    plain = fastdds_header_probe(READER_PROBE % 0, tmp_path)
    secure = fastdds_header_probe(READER_PROBE % 1, tmp_path)
    move = secure[0] - plain[0]
    assert 0 < move <= 64 and secure[1] - plain[1] == move, (plain, secure)
