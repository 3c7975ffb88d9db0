"""Rate-limited and polled subscriptions (cft_action.topics.rate), against publishers in other
processes, guarded (the publisher decides) and not (this process's reader decides)."""

import math
import time
from collections import Counter

import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Int32

from action_msgs.msg import GoalStatus
from test_msgs.action import Fibonacci
from rclpy.action import ActionClient as RclpyActionClient

from cft_action import _rcl
from cft_action.topics.rate import RateFilter
from cft_action import (ActionClient, create_filtered_subscription, guard, InvalidArgumentError,
                        poll, rate_filter_state, set_max_rate, stop_polling)
from harness.proc import stop_all
from harness.ros import unique_name
from tests.support import action_server, helper_process, prove_feedback_path, result_of, send

# Reliable with a short history: a reader that the writer filters must never stall on its gaps.
QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
SOURCE_HZ = 100
# Each publisher's messages are BASE + i: the hundreds say which publisher sent one.
BASES = (0, 100000)


MODES = ('guarded', 'unguarded')


def start_publishers(mode):
    """Two publishers of ints on one topic, each in its own process, started (the caller waits
    for their READY): the topic and the processes."""
    prefix = '/' + unique_name('cft_rate')
    env = guard.environment() if mode == 'guarded' else None
    return prefix + '/ints', [helper_process('tests.helpers.publisher', [prefix, 10], env=env,
                                             ready='') for _ in BASES]


@pytest.fixture
def runs():
    """Guarded and unguarded publishers, side by side, started together: mode -> (topic,
    processes)."""
    started = {}
    try:
        for mode in MODES:
            started[mode] = start_publishers(mode)
        for _, children in started.values():
            for child in children:
                child.expect('READY', 30)
        yield started
    finally:
        stop_all(child for _, children in started.values() for child in children)


def subscribe(ros, topic, qos=QOS, **rate):
    received: list[int] = []
    subscription = create_filtered_subscription(ros.node, Int32, topic,
                                                lambda m: received.append(m.data), qos, **rate)
    return subscription, received


def per_publisher(received):
    return Counter(data // BASES[1] for data in received)


def publish(ros, seconds, *groups):
    """Each group's publishers (one per BASES) at SOURCE_HZ for the same ``seconds``, while this
    process spins."""
    children = [child for group in groups for child in group]
    for child in children:
        assert child.request('wait ints 1', 'MATCHED') == 'MATCHED'
    for group in groups:
        for child, base in zip(group, BASES):
            child.send(f'steady {SOURCE_HZ} {seconds} {base}')
    for child in children:
        ros.spin_until(lambda c=child: c.last('SENT') is not None, timeout=seconds + 20)


def assert_where(ros, subscription, mode):
    state = rate_filter_state(subscription, ros.node)
    assert state.layout_mismatches == 0, state
    if mode == 'guarded':
        assert state.filtered_in == 'writer', state
        assert state.reader_verdicts == 0, state  # the writers decided: no re-evaluation
    else:
        assert state.filtered_in in ('reader', 'unknown'), state
        assert state.reader_verdicts > 0, state


def max_rate_run(ros, runs, hz, seconds):
    """A ``max_rate=hz`` subscription of each run, its publishers at SOURCE_HZ for ``seconds``:
    0.9-1.0x of ``hz`` per publisher. Returns the subscriptions by mode."""
    subscribed = {mode: subscribe(ros, topic, max_rate=hz) for mode, (topic, _) in runs.items()}
    publish(ros, seconds, *(children for _, children in runs.values()))
    ros.spin_for(0.5)
    for mode, (_, received) in subscribed.items():
        counts = per_publisher(received)
        for index in range(len(BASES)):
            # at most one per 1/HZ (the first comes at once), and the first after each interval
            assert 0.9 * hz * seconds <= counts[index] <= hz * seconds + 1, (mode, counts)
    return {mode: subscription for mode, (subscription, _) in subscribed.items()}


def test_max_rate_per_publisher(ros, runs):
    """0.9-1.0x of HZ per publisher over 5 s, guarded and unguarded publishers side by side."""
    for mode, subscription in max_rate_run(ros, runs, 10, 5).items():
        assert_where(ros, subscription, mode)
    for child in runs['guarded'][1]:
        # the subscriber alone on the writer: its GAP for the withheld run rides in the DATA
        counts = child.request_json('heartbeats', 'HEARTBEATS')
        assert counts['gaps_merged'] > 0 and counts['merges_dropped'] == 0, counts


def three_polls(ros, runs):
    """Three polls of 2 on a ``poll=0`` subscription of each run, its publishers at SOURCE_HZ for
    6 s: exactly 2 more of each publisher after each, nothing before the first; then
    stop_polling takes every message again. Returns the subscriptions by mode, once every
    publisher has sent all."""
    polled = {mode: subscribe(ros, topic, poll=0) for mode, (topic, _) in runs.items()}
    children = [child for _, group in runs.values() for child in group]
    for child in children:
        assert child.request('wait ints 1', 'MATCHED') == 'MATCHED'
    for _, group in runs.values():
        for child, base in zip(group, BASES):
            child.send(f'steady {SOURCE_HZ} 6 {base}')
    ros.spin_for(0.5)
    assert all(received == [] for _, received in polled.values())  # nothing until a poll
    for round_ in range(1, 4):
        for subscription, _ in polled.values():
            poll(subscription, 2)
        assert ros.spin_until(lambda r=round_: all(len(received) >= 4 * r
                                                   for _, received in polled.values()),
                              timeout=3), polled
        ros.spin_for(0.3)  # nothing more comes
        for mode, (_, received) in polled.items():
            assert per_publisher(received) == {0: 2 * round_, 1: 2 * round_}, (mode, received)
    for subscription, _ in polled.values():
        assert rate_filter_state(subscription, ros.node).polled == 6
        stop_polling(subscription)
    assert ros.spin_until(lambda: all(len(received) > 30 for _, received in polled.values()),
                          timeout=3), {mode: per_publisher(received)
                                       for mode, (_, received) in polled.items()}
    for child in children:
        ros.spin_until(lambda c=child: c.last('SENT') is not None, timeout=20)
    return {mode: subscription for mode, (subscription, _) in polled.items()}


def test_polls_are_exact_per_publisher(ros, runs):
    """Three polls of 2, guarded and unguarded publishers side by side (three_polls)."""
    for mode, subscription in three_polls(ros, runs).items():
        assert_where(ros, subscription, mode)


def test_max_rate_can_be_lifted_at_run_time(ros, runs):
    """Guarded and unguarded publishers side by side: a subscription made with ``max_rate=2`` and
    lifted at once takes every message of each."""
    subscribed = {}
    for mode, (topic, _) in runs.items():
        # A deep history: what is measured is the lifted filter, not how far this process lags.
        subscription, received = subscribe(ros, topic, QoSProfile(
            depth=1000, reliability=ReliabilityPolicy.RELIABLE), max_rate=2)
        set_max_rate(subscription, None)
        assert rate_filter_state(subscription, ros.node).max_rate is None
        subscribed[mode] = received
    ros.spin_for(0.5)  # the change reaches the writers by discovery, on a loaded machine later
    publish(ros, 2, *(children for _, children in runs.values()))
    ros.spin_for(0.5)
    # Once the change has arrived (within the first second), every message passes: of the second
    # second's, at least 0.9x came (the writers' keep-last 10 may replace a message that a loaded
    # machine did not acknowledge in time).
    for mode, received in subscribed.items():
        for base in BASES:
            second = [d for d in received if base + SOURCE_HZ <= d < base + 2 * SOURCE_HZ]
            assert len(second) >= 0.9 * SOURCE_HZ, (mode, base, per_publisher(received))


@pytest.mark.parametrize('mode', ['guarded', 'unguarded'])
def test_active_subscription_count_is_exact_under_the_guard(ros, mode):
    """A publisher with three subscriptions, polled, rate-limited and plain: under the guard it
    counts only those that would take a message published now; elsewhere the matched count."""
    prefix = '/' + unique_name('cft_active')
    child = helper_process('tests.helpers.publisher', [prefix, 10],
                           env=guard.environment() if mode == 'guarded' else None)
    try:
        polled, received = subscribe(ros, prefix + '/ints', poll=0)
        subscribe(ros, prefix + '/ints', max_rate=0.05)  # one message per 20 s
        ros.node.create_subscription(Int32, prefix + '/ints', lambda m: None, QOS)
        assert child.request('wait ints 3', 'MATCHED') == 'MATCHED'

        def active():
            return tuple(int(n) for n in child.request('active ints', 'ACTIVE').split()[1:])

        def settles_at(wanted):  # a poll reaches the writer by discovery
            return ros.spin_until(lambda: active() == (wanted, 3), timeout=10)

        guarded = mode == 'guarded'
        assert active() == (2 if guarded else 3, 3)  # the poll has nothing left
        assert child.request('burst 1', 'SENT') == 'SENT 1'
        assert settles_at(1 if guarded else 3)  # and the rate window is now closed
        poll(polled, 1)
        assert settles_at(2 if guarded else 3)
        assert child.request('burst 1', 'SENT') == 'SENT 1'
        assert ros.spin_until(lambda: len(received) == 1, timeout=10), received
        assert active() == (1 if guarded else 3, 3)
    finally:
        child.stop()


@pytest.mark.parametrize('rate, message', [
    ({'max_rate': 0}, 'max_rate=0'), ({'max_rate': -1.0}, 'max_rate=-1.0'),
    ({'max_rate': math.nan}, 'max_rate=nan'), ({'max_rate': 'fast'}, "max_rate='fast'"),
    ({'poll': -1}, 'poll=-1'), ({'poll': 1.5}, 'poll=1.5'),
    ({'max_rate': 2, 'filter_expression': 'data > 1'}, 'take no filter expression'),
])
def test_bad_arguments_name_themselves_and_leave_no_subscription(ros, rate, message):
    before = len(list(ros.node.subscriptions))
    with pytest.raises(InvalidArgumentError, match=message.replace('(', r'\(')):
        create_filtered_subscription(ros.node, Int32, '/' + unique_name('bad'), print, QOS,
                                     **rate)
    assert len(list(ros.node.subscriptions)) == before


@pytest.mark.parametrize('max_rate', [1e-300, 1e-10, 2.0, 1e12])
def test_any_valid_max_rate_is_in_the_class_grammar(max_rate):
    """The grammar refuses periods past INT64_MAX ns (fuzz/README.md): slower rates are that one."""
    expression = RateFilter(max_rate, None).expression()
    assert _rcl.filter_class_accepts(_rcl.RATE_FILTER_CLASS, expression), expression
    assert not _rcl.filter_class_accepts(_rcl.RATE_FILTER_CLASS, f'period={2**63}')


def test_poll_needs_a_polled_subscription(ros):
    rated, _ = subscribe(ros, '/' + unique_name('rated'), max_rate=1)
    with pytest.raises(InvalidArgumentError, match='created without poll='):
        poll(rated, 1)
    with pytest.raises(InvalidArgumentError, match='created without poll='):
        stop_polling(rated)
    polled, _ = subscribe(ros, '/' + unique_name('polled'), poll=0)
    with pytest.raises(InvalidArgumentError, match='n=-1'):
        poll(polled, -1)
    plain = ros.node.create_subscription(Int32, '/' + unique_name('plain'), print, QOS)
    with pytest.raises(InvalidArgumentError, match='not created with max_rate or poll'):
        set_max_rate(plain, 1)


@pytest.mark.parametrize('mode', ['guarded', 'unguarded'])
def test_the_action_clients_feedback_max_rate_is_per_goal(ros, mode):
    """Two goals of a client at ``feedback_max_rate=5``, beside a plain client's goal, each
    published at 100 Hz for 1.5 s: each limited goal's callback gets at most one per 0.2 s (the
    first at once), the plain one every message; the results come as without a limit. The limit
    counts from when messages are taken, so the bound is over the span of the callbacks: an
    executor held up 0.2 s on a busy machine takes the rest of a goal's messages later (seen:
    9 callbacks, two of them for messages published 10 ms apart)."""
    action = '/' + unique_name('fib_rate')
    server = action_server(action, 0.01, env=guard.environment() if mode == 'guarded' else None)
    try:
        limited = ActionClient(ros.node, Fibonacci, action, feedback_max_rate=5)
        plain = RclpyActionClient(ros.node, Fibonacci, action)
        for client in (limited, plain):
            assert client.wait_for_server(timeout_sec=20)
            prove_feedback_path(ros.spin_until, client)
        received: dict[str, list[int]] = {'a': [], 'b': [], 'plain': []}
        times: dict[str, list[float]] = {name: [] for name in received}

        def record(message, name: str) -> None:
            received[name].append(message.feedback.sequence[0])
            times[name].append(time.monotonic())

        handles = {name: send(ros, limited if name != 'plain' else plain, 150,
                              feedback_callback=lambda m, n=name: record(m, n))
                   for name in received}
        for handle in handles.values():
            assert result_of(ros, handle).status == GoalStatus.STATUS_SUCCEEDED
        ros.spin_for(0.3)
        assert len(received['plain']) == 150
        for name in 'ab':
            ks, span = received[name], times[name][-1] - times[name][0]
            # one at once, then at most one per 0.2 s; one more for a callback run late
            assert ks == sorted(ks) and 3 <= len(ks) <= span * 5 + 2, (name, ks, span)
    finally:
        server.stop()


def test_feedback_max_rate_must_be_above_0(ros):
    for bad in (0, -2.0, math.inf, 'fast', True):
        with pytest.raises(InvalidArgumentError, match=f'feedback_max_rate={bad!r}'):
            ActionClient(ros.node, Fibonacci, '/' + unique_name('fib'), feedback_max_rate=bad)
    assert not list(ros.node.clients)
