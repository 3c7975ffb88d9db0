"""The ctypes binding: clear errors at load, and the guarded private-layout access."""

import ctypes

import pytest
from test_msgs.action import Fibonacci

from cft_action import _rcl
from cft_action.action.client import ActionClient


def test_a_missing_symbol_is_a_clear_error_at_load():
    with pytest.raises(_rcl.BindingUnavailable, match='rcl_no_such_function'):
        _rcl._map_symbol(ctypes.CDLL(None), 'rcl_no_such_function', ctypes.c_int, [])


def test_rcl_errors_carry_rcl_error_string_and_reset_it():
    with pytest.raises(_rcl.ContentFilterError, match='not a valid rcl subscription') as info:
        _rcl.set_content_filter(0, 'data > 1')
    assert info.value.function == 'rcl_subscription_is_valid'
    assert _rcl.take_rcl_error() in ('', 'error not set')  # nothing left behind


def test_layout_check_finds_the_feedback_subscription_and_refuses_a_wrong_name(ros):
    client = ActionClient(ros.node, Fibonacci, 'layout_check', feedback_filter='off')
    pointer = client._client_handle.pointer
    found, reason = _rcl.action_feedback_subscription(
        pointer, ros.node.resolve_topic_name('layout_check'))
    assert found and reason == ''
    assert _rcl.subscription_topic_name(found) == '/layout_check/_action/feedback'
    missing, reason = _rcl.action_feedback_subscription(pointer, '/another_action')
    assert missing is None and 'layout check failed' in reason
    client.destroy()


def test_layout_check_finds_the_result_client_and_takes_nothing_from_empty_queues(ros):
    client = ActionClient(ros.node, Fibonacci, 'layout_check', feedback_filter='off')
    pointer = client._client_handle.pointer
    found, reason = _rcl.action_result_client(pointer, ros.node.resolve_topic_name('layout_check'))
    assert found and reason == '' and found == client._entities.result_client
    missing, reason = _rcl.action_result_client(pointer, '/another_action')
    assert missing is None and 'layout check failed' in reason
    with client:
        data: dict = {}
        assert client._entities.take_result_into(data) == 0 and data == {}
        assert client._entities.take_feedback() == (None, 0)
    client.destroy()


def test_a_client_whose_entities_cannot_be_located_keeps_rclpy_takes(ros, monkeypatch):
    monkeypatch.setattr(_rcl, 'action_result_client',
                        lambda pointer, name: (None, 'layout check failed: forced by the test'))
    client = ActionClient(ros.node, Fibonacci, 'layout_check')
    assert client._entities.result_client is None and not client._entities.takes_here
    # Without sample info there is no ordering evidence: feedback after a result is dropped.
    for goal_uuid in (b'g' * 16, b'h' * 16):
        client._feedback_callbacks[goal_uuid] = lambda _: None
    client._finished_goals.result(b'g' * 16, 0)
    assert client._finished_goals.dropped(b'g' * 16, 0)
    assert not client._finished_goals.dropped(b'h' * 16, 0)
    client.destroy()
