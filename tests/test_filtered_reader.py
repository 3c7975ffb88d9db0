"""The filtered-reader core: one state machine for every filtered subscription, on real rcl ones."""

import pytest
from test_msgs.action import Fibonacci
from rclpy.qos import QoSProfile
from std_msgs.msg import Int32

from cft_action import _rcl, ActionClient, ContentFilterError, ContentFilterOptions
from cft_action.topics import filters
from cft_action.topics._filtered_reader import FilteredReader, has_filter, ReaderFilterState
from cft_action.action.goal_filter import MAX_EXPRESSION_BYTES
from cft_action.topics.subscription import create_filtered_subscription
from harness.ros import unique_name

NEVER = ContentFilterOptions('data = 1 AND data = 2', [])
MATCH_ALL = 'data = data'


@pytest.fixture
def reader(ros):
    topic = '/' + unique_name('cft_core')
    subscription = create_filtered_subscription(ros.node, Int32, topic, lambda _: None,
                                                QoSProfile(depth=10), *NEVER)
    core = FilteredReader(ros.node.get_logger(), unfiltered='test filter not used',
                          match_all=MATCH_ALL)
    with subscription.handle:
        core.adopt(subscription.handle, subscription.handle.pointer, topic, NEVER)
    yield core
    ros.node.destroy_subscription(subscription)


def test_changes_are_in_place_and_counted(reader):
    assert reader.change(ContentFilterOptions('data > %0', ['5']))
    assert not reader.change(ContentFilterOptions('data > %0', ['5'])), 'same filter: no event'
    assert reader.state == ReaderFilterState(True, '', 'data > %0', ('5',), 1)
    assert reader.read() == ('data > %0', ['5'])


@pytest.mark.parametrize('options, named', [
    (ContentFilterOptions('', []), 'empty filter expression'),
    (ContentFilterOptions('data >', []), "'data >'"),
    (ContentFilterOptions("data LIKE '[x'", []), 'LIKE'),
], ids=['empty', 'syntax', 'pattern'])
def test_a_rejected_change_names_it_and_keeps_the_filter(reader, options, named):
    with pytest.raises(ContentFilterError, match=named):
        reader.change(options)
    assert reader.state == ReaderFilterState(True, '', NEVER.filter_expression, (), 0)
    assert reader.read() == NEVER


def test_a_failed_update_abandons_the_filter_in_place_for_good(reader):
    reader.update(ContentFilterOptions('data >', []))
    state = reader.state
    assert (state.active, state.expression, state.updates) == (False, '', 1)
    assert state.reason.startswith("a filter update failed: content filter 'data >'")
    assert reader.read() == (MATCH_ALL, []), 'everything passes, on the same reader'
    reader.update(ContentFilterOptions('data > 1', []))
    assert reader.state == state, 'an abandoned filter never comes back'
    with pytest.raises(ContentFilterError, match='a filter update failed'):
        reader.change(ContentFilterOptions('data > 1', []))


def test_a_filter_class_this_fast_dds_lacks_falls_back_naming_why(ros, monkeypatch):
    # As on Kilted's wheels (Fast DDS 3): the class's part cannot load, so rcl is never called and
    # there is no rcl error string; the reason is the part's own, never an empty one.
    cause = 'not loaded: libfastrtps.so.2.14: cannot open shared object file'
    monkeypatch.setattr(_rcl, 'filter_class_status', lambda: cause)
    topic = '/' + unique_name('cft_core_class')
    subscription = ros.node.create_subscription(Int32, topic, lambda _: None, 10)
    core = FilteredReader(ros.node.get_logger(), unfiltered='test filter not used',
                          match_all=MATCH_ALL, filter_class=_rcl.UUID_FILTER_CLASS)
    with subscription.handle:
        assert not core.install(subscription.handle, subscription.handle.pointer, topic, NEVER)
        assert not has_filter(subscription.handle.pointer), 'the subscription was not touched'
    assert core.state == ReaderFilterState(False, core.state.reason, '', (), 0)
    assert core.state.reason == (
        f'installing the filter failed: content filter {NEVER.filter_expression!r} with '
        f'parameters [] on {topic} was not set: the {_rcl.UUID_FILTER_CLASS} filter class (built '
        f'for Fast DDS 2.14 only) cannot be used: {cause}')


def test_an_rcl_failure_without_an_error_string_still_says_what_failed(reader, monkeypatch):
    taken = []
    real = _rcl.take_rcl_error
    monkeypatch.setattr(_rcl, 'take_rcl_error', lambda: (taken.append(real()), '')[1])
    with pytest.raises(ContentFilterError, match=r'was rejected: rcl_subscription_set_content_'
                       r'filter returned RCL_RET_\w+: rcl set no error string$'):
        reader.change(ContentFilterOptions('no_such_field = 1', []))
    assert taken, 'rcl failed, and its error state was reset'
    assert reader.read() == NEVER


def test_no_call_reaches_a_detached_reader(reader):
    reader.detach('destroyed')
    assert reader.ended and reader.read() == ('', [])
    reader.update(ContentFilterOptions('data > 1', []))
    with pytest.raises(ContentFilterError, match='destroyed'):
        reader.change(ContentFilterOptions('data > 1', []))


def test_a_client_whose_filter_outgrows_discovery_lets_all_feedback_through(ros):
    # Caller-supplied UUIDs are matched on all 16 bytes: about 400 bytes a goal.
    client = ActionClient(ros.node, Fibonacci, unique_name('cft_core_action'))
    try:
        goals = MAX_EXPRESSION_BYTES // 400 + 10
        for _ in range(goals):
            uuid = client.new_goal_uuid()
            uuid.uuid[0] ^= 0xFF  # not the client's tag: a term of its own
            client.send_goal_async(Fibonacci.Goal(), feedback_callback=lambda _: None,
                                   goal_uuid=uuid)
            if not client.feedback_filter_state.active:
                break
        state = client.feedback_filter_state
        assert not state.active, state
        assert 'a filter update failed' in state.reason, state
        assert str(MAX_EXPRESSION_BYTES) in state.reason, state
        assert state.expression == '' and state.live_goals == 0
        assert client._reader.read() == (filters.MATCH_ALL, []), 'all feedback passes, in place'
    finally:
        client.destroy()
