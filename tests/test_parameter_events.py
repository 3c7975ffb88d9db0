"""The filtered ParameterEventHandler against parameter events published by another process."""

import os
import signal
import time
from typing import NamedTuple, Optional

import pytest
from rclpy.parameter_event_handler import ParameterEventHandler as RclpyParameterEventHandler

import cft_action.parameters.parameter_events
from cft_action import ContentFilterError, guard, is_filtered
from cft_action.parameters.parameter_events import (ALL_NODES, NO_NODES, ParameterEventHandler,
                                         node_filter)
from harness.ros import unique_name
from tests.support import helper_process, prove_parameter_events

BURST = 20
SYNC_TIMEOUT = 15.0


class Recorder:
    """Parameter callbacks that record, per node, the values they were called with, and when."""

    def __init__(self, handler, parameter='value'):
        self.handler = handler
        self.parameter = parameter
        self.values = {}
        self.arrivals = {}  # per node, time.monotonic() of each value
        self.handles = {}

    def watch(self, node_name):
        self.values.setdefault(node_name, [])
        self.arrivals.setdefault(node_name, [])
        self.handles[node_name] = self.handler.add_parameter_callback(
            self.parameter, node_name, lambda p, n=node_name: self.record(n, p))
        return self.handles[node_name]

    def record(self, node_name, parameter):
        self.values[node_name].append(parameter.value.integer_value)
        self.arrivals[node_name].append(time.monotonic())

    def unwatch(self, node_name):
        self.handler.remove_parameter_callback(self.handles.pop(node_name))


@pytest.fixture
def prefix():
    return '/' + unique_name('cft_pe')


@pytest.fixture
def start_nodes():
    """Start param_nodes.py with the given node names; stops every process it started.

    The nodes run under the guard: every filter change is an event at each of their
    /parameter_events writers, and the tests publish right after changes (to sync), which is when
    an unguarded Fast DDS 2.14 writer can crash (docs/INTERNALS.md section 10; tests/test_guard.py
    covers that hazard itself).
    """
    children = []

    def start(*names):
        child = helper_process('harness.param_nodes', names, env=guard.environment())
        children.append(child)
        return child

    yield start
    for child in children:
        alive = child.poll() is None
        ended = child.stop()
        assert alive, f'param_nodes.py died\n{child.tail()}'
        # A peer that aborts at exit can crash this process later (harness.ros)
        assert ended == 0, f'param_nodes.py did not end cleanly\n{child.tail()}'


def in_force(ros, handler, names, timeout=SYNC_TIMEOUT):
    """Return once the publishers of ``names`` apply the handler's current filter.

    Used where a filter change adds no node to sync on, or removes one. The handler can only
    prove the change to the publishers it knows, so first wait until it knows theirs.
    """
    def known():
        return {f"{i.node_namespace.rstrip('/')}/{i.node_name}"
                for i in ros.node.get_publishers_info_by_topic('/parameter_events')}
    assert ros.spin_until(lambda: set(names) <= known(), timeout), \
        f'no publisher of {set(names) - known()} discovered within {timeout} s'
    assert handler.wait_for_filter(timeout), f'the filter change not proven within {timeout} s'
    assert handler.parameter_event_filter_state.confirmed


class Burst(NamedTuple):
    """What one burst delivered, and the evidence that a failure's message carries."""

    received: int
    evidence: str


def burst(ros, handler, child, count=BURST, expected=0, settle=1.0, *, proof: str = '',
          recorder: Optional[Recorder] = None) -> Burst:
    """Publish ``count`` changes of ``value`` on every node; return the events received.

    With the evidence of a miss that a rerun would not show (once, 18 of 20 events after the
    proof of the event path, cause unknown): ``proof`` (what :func:`prove_parameter_events`
    returned), the handler's filter state before and after, when the nodes answered and when the
    events came, what each of ``recorder``'s callbacks got and when, and the /parameter_events
    publishers that this node knows.
    """
    before = handler.parameter_event_filter_state
    progress = []  # (seconds after the request, events received so far), at each change

    def received_enough():
        received = handler.parameter_event_filter_state.events_received - before.events_received
        if not progress or progress[-1][1] != received:
            progress.append((round(time.monotonic() - start, 3), received))
        return received >= expected

    start = time.monotonic()
    child.request(f'burst {count}', 'BURST', timeout=60)
    answered = time.monotonic() - start
    ros.spin_until(received_enough, 15)
    ros.spin_for(settle)  # anything that should not arrive has had its chance
    received_enough()
    after = handler.parameter_event_filter_state
    received = after.events_received - before.events_received
    timeline = progress if len(progress) <= 8 else [*progress[:4], '...', *progress[-4:]]
    publishers = sorted(f"{i.node_namespace.rstrip('/')}/{i.node_name}"
                        for i in ros.node.get_publishers_info_by_topic('/parameter_events'))
    lines = [f'{received} events of {expected} expected, {count} changes per node; {proof}',
             f'the nodes answered BURST after {answered:.3f} s; events over time (s, count): '
             f'{timeline}',
             f'filter before: {before}', f'filter after: {after}',
             f'/parameter_events publishers known here: {publishers}']
    for name, values in (recorder.values.items() if recorder else ()):
        arrivals = [round(t - start, 3) for t in recorder.arrivals.get(name, [])]
        lines.append(f'{name}: values {values}, at (s) {arrivals}')
    return Burst(received, '\n'.join(lines))


def test_is_a_drop_in(ros):
    handler = ParameterEventHandler(ros.node)
    assert isinstance(handler, RclpyParameterEventHandler)
    assert is_filtered(handler.parameter_event_subscription)
    state = handler.parameter_event_filter_state
    assert (state.mode, state.active, state.expression, state.updates, state.confirmed) == \
        ('nodes', True, NO_NODES, 0, True)
    assert handler.get_parameter_event_filter() == (NO_NODES, [])
    assert handler.wait_for_filter(0)  # nothing changed since the creation
    handler.destroy()
    assert handler.parameter_event_filter_state.mode == 'off'
    assert handler.get_parameter_event_filter() == ('', [])


def test_callbacks_fire_for_watched_nodes_only_and_miss_nothing(ros, start_nodes, prefix):
    watched = [f'{prefix}/a', f'{prefix}/ns/b']
    unwatched = [f'{prefix}/c', f'{prefix}/d', f'{prefix}/ns/e']
    child = start_nodes(*watched, *unwatched)
    handler = ParameterEventHandler(ros.node)
    recorder = Recorder(handler)
    for name in watched:
        recorder.watch(name)
    assert child.request('matched 1', 'MATCHED') == 'MATCHED'
    proof = prove_parameter_events(ros, handler, child, watched)

    sent = burst(ros, handler, child, expected=len(watched) * BURST, proof=proof,
                 recorder=recorder)

    for name in watched:
        assert recorder.values[name] == list(range(1, BURST + 1)), f'{name}\n{sent.evidence}'
    # The unwatched nodes' events never reached this process: filtered by their writers.
    assert sent.received == len(watched) * BURST, sent.evidence
    state = handler.parameter_event_filter_state
    assert state.watched_nodes == tuple(sorted(watched))
    assert state.updates == 2


def in_class(*names):
    """The filter a default handler sets: the library's node class takes the names inline."""
    return node_filter(names, parameters=False)


def test_adding_and_removing_callbacks_grows_and_shrinks_the_filter(ros, start_nodes, prefix):
    a, b, c = f'{prefix}/a', f'{prefix}/b', f'{prefix}/c'
    child = start_nodes(a, b, c)
    handler = ParameterEventHandler(ros.node)
    recorder = Recorder(handler)
    assert child.request('matched 1', 'MATCHED') == 'MATCHED'

    recorder.watch(a)
    assert handler.get_parameter_event_filter() == in_class(a)
    recorder.watch(b)
    state = handler.parameter_event_filter_state
    assert (state.expression, state.expression_parameters) == (in_class(a, b).filter_expression, ())
    assert handler.get_parameter_event_filter() == (state.expression,
                                                    list(state.expression_parameters))
    assert state.updates == 2
    # A second callback on a watched node, for another parameter, changes nothing.
    extra = handler.add_parameter_callback('other', a, lambda p: None)
    assert handler.parameter_event_filter_state.updates == 2
    proof = prove_parameter_events(ros, handler, child, [a, b])
    sent = burst(ros, handler, child, expected=2 * BURST, proof=proof, recorder=recorder)
    assert sent.received == 2 * BURST, sent.evidence
    assert recorder.values[b] == list(range(1, BURST + 1)), sent.evidence

    # Shrink: b leaves the filter. Adding c right after proves, once c's events arrive, that the
    # writers (all in one participant) have the newer filter, which has no b either.
    recorder.unwatch(b)
    assert handler.get_parameter_event_filter() == in_class(a)
    recorder.watch(c)
    proof = prove_parameter_events(ros, handler, child, [a, c])
    recorder.values[b].clear()
    sent = burst(ros, handler, child, expected=2 * BURST, proof=proof, recorder=recorder)
    assert sent.received == 2 * BURST, sent.evidence
    assert recorder.values[b] == [], sent.evidence
    assert recorder.values[c] == list(range(1, BURST + 1)), sent.evidence
    assert handler.parameter_event_filter_state.updates == 4

    handler.remove_parameter_callback(extra)
    recorder.unwatch(a)
    recorder.unwatch(c)
    state = handler.parameter_event_filter_state
    assert (state.expression, state.watched_nodes, state.updates) == (NO_NODES, (), 6)
    assert handler.get_parameter_event_filter() == (NO_NODES, [])


def test_node_names_that_need_quoting(ros, start_nodes, prefix):
    # Slashes, and names that are DDS-SQL keywords: only a quoted literal compares them right.
    tricky = f'{prefix}/OR/AND'
    other = f'{prefix}/TRUE/x_1/LIKE'
    child = start_nodes(tricky, other, f'{prefix}/OR/NOT')
    handler = ParameterEventHandler(ros.node)
    recorder = Recorder(handler)
    # A relative name resolves against the handler node's namespace, as in rclpy: here '/'.
    recorder.watch(tricky)
    relative = handler.add_parameter_callback(
        'value', other.lstrip('/'), lambda p: recorder.values[other].append(
            p.value.integer_value))
    recorder.values[other] = []
    assert relative.node_name == other
    assert handler.get_parameter_event_filter() == in_class(tricky, other)
    assert child.request('matched 1', 'MATCHED') == 'MATCHED'
    proof = prove_parameter_events(ros, handler, child, [tricky, other])
    sent = burst(ros, handler, child, expected=2 * BURST, proof=proof, recorder=recorder)
    assert sent.received == 2 * BURST, sent.evidence
    assert recorder.values[tricky] == recorder.values[other] == list(range(1, BURST + 1)), \
        sent.evidence


def test_unquotable_node_name_is_left_out_of_the_filter(ros):
    handler = ParameterEventHandler(ros.node)
    handle = handler.add_parameter_callback('p', "/it's", lambda p: None)
    state = handler.parameter_event_filter_state
    assert (state.expression, state.updates, state.watched_nodes) == (NO_NODES, 0, ("/it's",))
    handler.remove_parameter_callback(handle)
    with pytest.raises(RuntimeError):  # as rclpy: an unknown handle
        handler.remove_parameter_callback(handle)


def test_more_nodes_than_expression_parameters(ros):
    names = [f'/n{i:03d}' for i in range(120)]
    expression, parameters = node_filter(names)
    assert parameters == [] and expression.startswith("node = '/n000' OR node = '/n001'")
    handler = ParameterEventHandler(ros.node)
    for name in names:
        handler.add_parameter_callback('p', name, lambda p: None)
    assert handler.get_parameter_event_filter() == (expression, [])
    assert handler.parameter_event_filter_state.updates == 120


def test_configure_nodes_filter_is_the_newer_distros_name(ros):
    """Lyrical's rclpy has configure_nodes_filter(node_names) -> bool (rclpy#1531)."""
    handler = ParameterEventHandler(ros.node)
    assert handler.configure_nodes_filter(['/b', '/a'])
    assert handler.get_parameter_event_filter() == in_class('/a', '/b')
    assert not handler.configure_nodes_filter(["/it's"])  # no DDS literal holds a quote
    assert handler.get_parameter_event_filter() == in_class('/a', '/b')
    assert handler.configure_nodes_filter(None)
    assert handler.get_parameter_event_filter() == (NO_NODES, [])  # no callback watches a node


def test_user_expression_with_syntax_error_raises_naming_it(ros, start_nodes, prefix):
    a = f'{prefix}/a'
    child = start_nodes(a)
    handler = ParameterEventHandler(ros.node, writer_filtering='any')  # DDS-SQL of one's own
    recorder = Recorder(handler)
    recorder.watch(a)
    before = handler.parameter_event_filter_state

    with pytest.raises(ContentFilterError) as info:
        handler.set_parameter_event_filter('node = = %0', [a])
    assert "'node = = %0'" in str(info.value)
    assert "stays 'node = %0'" in str(info.value)
    with pytest.raises(ContentFilterError, match="'nodes = %0'"):
        handler.set_parameter_event_filter('nodes = %0', [a])  # no such field
    with pytest.raises(ContentFilterError, match="'node = %0'.*quote"):
        handler.set_parameter_event_filter('node = %0', ["/it's"])

    # The previous filter stays, and still works.
    assert handler.parameter_event_filter_state == before
    assert handler.get_parameter_event_filter() == ('node = %0', [f"'{a}'"])
    assert child.request('matched 1', 'MATCHED') == 'MATCHED'
    proof = prove_parameter_events(ros, handler, child, [a])
    sent = burst(ros, handler, child, expected=BURST, proof=proof, recorder=recorder)
    assert sent.received == BURST, sent.evidence
    assert recorder.values[a] == list(range(1, BURST + 1)), sent.evidence


def test_user_expression_and_event_callbacks(ros, start_nodes, prefix):
    a, b, c = f'{prefix}/a', f'{prefix}/b', f'{prefix}/c'
    child = start_nodes(a, b, c)
    handler = ParameterEventHandler(ros.node, writer_filtering='any')  # DDS-SQL of one's own
    recorder = Recorder(handler)
    recorder.watch(a)
    events = []

    # A node-agnostic event callback needs everything: unfiltered, and the state says why.
    handle = handler.add_parameter_event_callback(lambda e: events.append(e.node))
    state = handler.parameter_event_filter_state
    assert (state.mode, state.active, state.expression) == ('all', False, '')
    assert 'add_parameter_event_callback' in state.reason
    assert handler.get_parameter_event_filter() == (ALL_NODES, [])
    assert child.request('matched 1', 'MATCHED') == 'MATCHED'
    in_force(ros, handler, [a, b, c])
    proof = prove_parameter_events(ros, handler, child, [a, b, c])
    events.clear()
    sent = burst(ros, handler, child, expected=3 * BURST, proof=proof, recorder=recorder)
    assert sorted(set(events)) == [a, b, c] and len(events) == 3 * BURST, sent.evidence

    # A user expression, bare names quoted automatically; it wins over the event callback.
    handler.set_parameter_event_filter('node = %0 OR node = %1', [a, c])
    assert handler.get_parameter_event_filter() == ('node = %0 OR node = %1',
                                                    [f"'{a}'", f"'{c}'"])
    state = handler.parameter_event_filter_state
    assert (state.mode, state.active, state.expression) == ('user', True, 'node = %0 OR node = %1')
    # Watching b now does not change a user filter.
    recorder.watch(b)
    assert handler.parameter_event_filter_state.updates == state.updates
    in_force(ros, handler, [a, b, c])
    proof = prove_parameter_events(ros, handler, child, [a, c])
    events.clear()
    sent = burst(ros, handler, child, expected=2 * BURST, proof=proof, recorder=recorder)
    assert sorted(set(events)) == [a, c] and len(events) == 2 * BURST, sent.evidence

    # Clearing it hands the filter back to the handler: all nodes while the event callback lives.
    handler.set_parameter_event_filter('')
    assert handler.parameter_event_filter_state.mode == 'all'
    handler.remove_parameter_event_callback(handle)
    state = handler.parameter_event_filter_state
    assert (state.mode, state.active) == ('nodes', True)
    assert handler.get_parameter_event_filter() == ('node = %0 OR node = %1',
                                                    [f"'{a}'", f"'{b}'"])


def test_a_change_is_unconfirmed_until_the_publishers_have_it(ros, start_nodes, prefix):
    """A filter change that has not reached the publishers never looks applied.

    Discovery brings a change to the publishers' process some time later; stopping that process
    stretches the time to as long as the test needs. Until the change is proven there, the state
    says it is unconfirmed, even in mode 'all', where the change only lets more through: the old
    filter would still drop the events of b.
    """
    a, b = f'{prefix}/a', f'{prefix}/b'
    child = start_nodes(a, b)
    handler = ParameterEventHandler(ros.node)
    Recorder(handler).watch(a)
    assert child.request('matched 1', 'MATCHED') == 'MATCHED'
    prove_parameter_events(ros, handler, child, [a])
    in_force(ros, handler, [a, b])  # b's writer has 'node = %0' too: it drops b's events
    events = []

    os.kill(child.pid, signal.SIGSTOP)
    try:
        handler.add_parameter_event_callback(lambda e: events.append(e.node))
        state = handler.parameter_event_filter_state
        assert (state.mode, state.active, state.updates) == ('all', False, 2)
        assert not state.confirmed
        assert not handler.wait_for_filter(1.0)
        assert not handler.parameter_event_filter_state.confirmed
    finally:
        os.kill(child.pid, signal.SIGCONT)

    in_force(ros, handler, [a, b])
    proof = prove_parameter_events(ros, handler, child, [a, b])
    events.clear()
    sent = burst(ros, handler, child, expected=2 * BURST, proof=proof)
    assert sorted(set(events)) == [a, b] and len(events) == 2 * BURST, sent.evidence


def test_use_sim_time_still_flips_the_clock(ros, start_nodes, prefix):
    a = f'{prefix}/a'
    child = start_nodes(a)
    me = ros.node.get_fully_qualified_name()
    watching_other = ParameterEventHandler(ros.node)
    Recorder(watching_other).watch(a)
    watching_me = ParameterEventHandler(ros.node)
    seen = []
    watching_me.add_parameter_callback('use_sim_time', me,
                                       lambda p: seen.append(p.value.bool_value))
    clock = ros.node.get_clock()
    assert not clock.ros_time_is_active

    for value in (True, False):
        child.send(f'remote {me} use_sim_time {"true" if value else "false"}')
        # Spin: our parameter service must answer the other process.
        assert ros.spin_until(lambda value=value: clock.ros_time_is_active == value, timeout=20), \
            f'use_sim_time={value} did not reach the clock'
        assert child.expect('REMOTE', timeout=20) == 'REMOTE OK'
        assert ros.spin_until(lambda value=value: len(seen) >= (1 if value else 2), timeout=5)
    assert seen == [True, False]
    # The handler that watches another node did not receive this node's events.
    assert watching_other.parameter_event_filter_state.events_received == 0


def test_falls_back_when_the_rmw_has_no_content_filter(ros, monkeypatch):
    monkeypatch.setattr(cft_action.parameters.parameter_events, 'is_content_filter_supported',
                        lambda node: False)
    handler = ParameterEventHandler(ros.node)
    handler.add_parameter_callback('p', '/x', lambda p: None)
    state = handler.parameter_event_filter_state
    assert (state.mode, state.active, state.updates) == ('off', False, 0)
    assert 'no content filter' in state.reason
    assert not is_filtered(handler.parameter_event_subscription)
    assert handler.get_parameter_event_filter() == ('', [])
    with pytest.raises(ContentFilterError, match='no content filter'):
        handler.set_parameter_event_filter('node = %0', ['/x'])
