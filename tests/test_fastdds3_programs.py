"""Rate-limited and polled subscriptions and parameter events on Fast DDS 3.3+ (Lyrical), where
the library's classes cannot be a content filter: the reader marks its program (USER_DATA),
guarded publishers apply it to that reader, and this process applies it too, per publisher
(cft_action/topics/_program_mark.py, cft_action/native/guard/_guard_programs.c)."""

from __future__ import annotations

import pytest

from cft_action import _rcl, guard, rate_filter_state
from cft_action.parameters.parameter_events import ParameterEventHandler
from harness.proc import stop_all
from harness.ros import unique_name
from tests.support import helper_process, prove_parameter_events
from tests.test_fastdds3 import _fast_dds_3
from tests.test_fastdds3_replies import MISSING
from tests.test_parameter_events import BURST, burst, Recorder
# The lifted rate runs here as on Jazzy: the lifted program reaches the guarded writers.
from tests.test_rate_limit import (max_rate_run, publish, QOS, runs, SOURCE_HZ,  # noqa: F401
                                   test_max_rate_can_be_lifted_at_run_time, three_polls)

pytestmark = pytest.mark.skipif(not _fast_dds_3(), reason="a Fast DDS 3 stack (Kilted's wheels)")
#: Whether guarded writers apply the marks here (Fast DDS 3.3+, the layers built): on Kilted's
#: 3.2.2 the subscriber alone applies the rules, per publisher.
ROUTED = MISSING is None


def program_counts(children):
    return [child.request_json('programs', 'PROGRAMS') for child in children]


def assert_where(ros, subscription, mode):
    state = rate_filter_state(subscription, ros.node)
    assert state.reason, state  # the class is not this reader's filter on Fast DDS 3
    assert state.filtered_in == ('writer' if mode == 'guarded' and ROUTED else 'python'), state


def test_max_rate_per_publisher(ros, runs):  # noqa: F811
    """0.9-1.0x of HZ per publisher over 5 s, guarded and unguarded publishers side by side
    (test_rate_limit.max_rate_run); the guarded ones withhold what the rate does not pass, the
    unguarded ones send everything."""
    hz, seconds = 10, 5
    for mode, subscription in max_rate_run(ros, runs, hz, seconds).items():
        assert_where(ros, subscription, mode)
    for counts in program_counts(runs['guarded'][1]):
        # each publisher sent SOURCE_HZ x seconds; all but about hz x seconds were withheld
        assert counts['withheld'] >= (0.8 * (SOURCE_HZ - hz) * seconds if ROUTED else 0), counts
        assert counts['refused'] == 0 and counts['writers'] >= ROUTED, counts
    assert program_counts(runs['unguarded'][1]) == [{}, {}]


def test_polls_are_exact_per_publisher(ros, runs):  # noqa: F811
    """Three polls of 2 (test_rate_limit.three_polls): exactly 2 more of each publisher after
    each, guarded or not; guarded publishers send only the polled messages."""
    for mode, subscription in three_polls(ros, runs).items():
        assert_where(ros, subscription, mode)
    withheld = [counts['withheld'] for counts in program_counts(runs['guarded'][1])]
    # Until the last poll each guarded publisher had sent at most its 6 polled messages (and a
    # few while a poll travelled to it); the rest of its 100 a second were withheld.
    assert all(count >= (100 if ROUTED else 0) for count in withheld), withheld


def test_parameter_events_of_unwatched_nodes_stay_in_guarded_nodes(ros):
    """A ParameterEventHandler watching one guarded and one unguarded node, beside an unwatched
    node of each: the callbacks get exactly their nodes' events; the guarded process withholds its
    unwatched node's events, the unguarded one sends them (and the handler drops them, as
    rclpy's does)."""
    prefix = '/' + unique_name('cft_pe3')
    guarded = helper_process('harness.param_nodes', [f'{prefix}/a', f'{prefix}/c'],
                             env=guard.environment())
    plain = helper_process('harness.param_nodes', [f'{prefix}/b', f'{prefix}/d'])
    try:
        handler = ParameterEventHandler(ros.node)
        recorder = Recorder(handler)
        watched = [f'{prefix}/a', f'{prefix}/b']
        for name in watched:
            recorder.watch(name)
        for child in (guarded, plain):
            assert child.request('matched 1', 'MATCHED') == 'MATCHED'
        proof = prove_parameter_events(ros, handler, guarded, [f'{prefix}/a'])
        proof += '; ' + prove_parameter_events(ros, handler, plain, [f'{prefix}/b'])
        before = guarded.request_json('programs', 'PROGRAMS')
        sent = [burst(ros, handler, child, expected=expected, proof=proof, recorder=recorder)
                for child, expected in ((guarded, BURST if ROUTED else 2 * BURST),
                                        (plain, 2 * BURST))]
        for name in watched:
            assert recorder.values[name] == list(range(1, BURST + 1)), (name, sent)
        # the guarded process sent a's events only (where the marks are applied); the plain one
        # sent b's and d's
        assert [s.received for s in sent] == [BURST if ROUTED else 2 * BURST, 2 * BURST], sent
        after = guarded.request_json('programs', 'PROGRAMS')
        assert after['withheld'] - before['withheld'] >= (BURST if ROUTED else 0), (before, after)
        assert after['refused'] == 0, after
        state = handler.parameter_event_filter_state
        assert state.mode == ('nodes' if ROUTED else 'off') and not state.active, state
        assert state.filtered_in == 'none', state
        handler.destroy()
    finally:
        stop_all([guarded, plain])


@pytest.mark.skipif(not ROUTED, reason=MISSING or '')
def test_a_mark_outside_the_grammars_is_refused_and_gets_every_sample(ros, runs):  # noqa: F811
    """A reader whose program mark no class compiles (as any participant may send): the guarded
    publishers refuse it, count it, and send that reader every sample, as an unguarded one."""
    from std_msgs.msg import Int32
    topic, children = runs['guarded']
    received = []
    subscription = ros.node.create_subscription(Int32, topic, lambda m: received.append(m.data),
                                                QOS)
    with subscription.handle:
        assert _rcl.mark_reader_program(subscription.handle.pointer, _rcl.RATE_FILTER_CLASS,
                                        'period=fast') == ''
    publish(ros, 1, children)
    ros.spin_for(0.5)
    assert len(received) >= 0.9 * SOURCE_HZ * len(children), len(received)
    for counts in program_counts(children):
        assert counts['refused'] >= 1 and counts['withheld'] == 0, counts
