"""The drop-in ActionClient against a real ActionServer in another process."""

import json
import shutil
import subprocess
import threading
import time
import uuid
from pathlib import Path

import pytest
from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient as RclpyActionClient
from rclpy.executors import MultiThreadedExecutor
from rclpy.qos import QoSProfile
from rclpy.task import Future
from test_msgs.action import Fibonacci
from unique_identifier_msgs.msg import UUID

import cft_action._rcl
import cft_action.action.client
from cft_action import ActionClient, guard
from cft_action.topics.filters import NEVER_MATCH
from harness.polling import wait_until
from harness.proc import stop_all
from harness.ros import RosSession, unique_name
from tests.support import (action_server, helper_process, prove_feedback_path, result_of,
                           round_trip, send, server_evidence)

PERIOD = 0.01  # 100 Hz feedback per goal


def start_server(action, *, guarded=True, period=PERIOD):
    env = guard.environment() if guarded else None
    return action_server(action, period, env=env)


@pytest.fixture
def server():
    """A guarded server; yields (action name, process); asserts the server survived."""
    action = '/' + unique_name('fib')
    child = start_server(action)
    try:
        yield action, child
        assert child.poll() is None, f'server died\n{child.tail()}'
    finally:
        child.stop()


def run_clients(server, action, mode, clients, goals, order, *, one_by_one=False):
    """Client processes (tests/helpers/fib_client.py), all ready, then all sending their goals;
    their reports. Each proved its feedback path before it was ready, so the server published
    feedback before the goals: ``server_published_since_go`` is what it published for the goals.

    They start together, their discoveries of the server (up to Fast DDS's 3 s announcement
    period each) overlapping; with ``one_by_one``, one after another ready, and
    ``server_published_since_ready`` is then what the server published after that client was
    ready (the later clients' proofs included), which a client that takes every sample took."""
    children, published_at_ready = [], []
    try:
        for _ in range(clients):
            children.append(helper_process('tests.helpers.fib_client',
                                           [action, mode, goals, order],
                                           ready='READY' if one_by_one else ''))
            if one_by_one:
                published_at_ready.append(server_published(server))
        if not one_by_one:
            for child in children:
                child.expect('READY', 60)
        published_at_go = server_published(server)
        for child in children:
            child.send('go')
        reports = [json.loads(c.expect('RESULT', timeout=90).split(' ', 1)[1]) for c in children]
        published = server_published(server)
        since_ready = [{'server_published_since_ready': published - ready}
                       for ready in published_at_ready] or [{}] * len(reports)
        return [{**report, **ready, 'server_published_since_go': published - published_at_go}
                for report, ready in zip(reports, since_ready)]
    finally:
        stop_all(children)


def server_published(child):
    return child.request_json('stats', 'STATS')['published']


@pytest.mark.parametrize('mode, guarded', [
    ('client', True), ('goals', True), ('off', True),
    ('client', False),  # the default mode is safe for an unguarded server at 100 Hz
], ids=['client', 'goals', 'off', 'client-unguarded-server'])
def test_three_clients_each_get_exactly_their_own_feedback(ros, mode, guarded):
    clients, goals, order = 3, 3, 10
    action = '/' + unique_name('fib')
    child = start_server(action, guarded=guarded)
    try:
        # 'off' takes every sample: one by one, so that what each client took after it was
        # ready is what the server published after it.
        reports = run_clients(child, action, mode, clients, goals, order,
                              one_by_one=mode == 'off')
        assert child.poll() is None, 'server died'
    finally:
        child.stop()
    own = goals * order
    for report in reports:
        assert report['server_published_since_go'] == clients * own
        assert report['results'] == goals
        assert report['complete_goals'] == goals, report
        assert report['own_received'] == own
        assert report['misrouted'] == 0
        if mode == 'off':
            assert not report['active'] and report['reason'] == 'feedback_filter is off'
            assert report['taken'] - report['proof_taken'] == \
                report['server_published_since_ready'], report
        else:
            assert report['active'], report['reason']
            assert report['taken'] - report['proof_taken'] == own, \
                f'foreign feedback was taken from rcl: {report}'
            assert report['dropped'] == 0


@pytest.mark.parametrize('mode, goals', [('client', 200)])
def test_feedback_published_in_the_first_line_of_execute_all_arrives(ros, server, mode, goals):
    action, child = server
    [report] = run_clients(child, action, mode, 1, goals, 3)
    assert report['active']
    assert report['complete_goals'] == goals, report
    assert report['updates'] == 0


@pytest.mark.parametrize('mode, goals', [('client', 500), ('goals', 200)])
def test_many_concurrent_goals_keep_the_filter_active(ros, mode, goals):
    action = '/' + unique_name('fib')
    # Each goal lives 3 s, so all are live at once, and the feedback stays near 1000 messages/s,
    # which one Python client on this 2-core machine takes without overflowing its queues.
    child = start_server(action, period=0.5)
    try:
        [report] = run_clients(child, action, mode, 1, goals, 6)
        assert child.poll() is None, 'server died'
    finally:
        child.stop()
    assert report['active'], report['reason']
    # goals mode holds a request whose UUID came with a filter update until the server's writer
    # has the update, so the feedback the server publishes at once arrives too
    assert report['complete_goals'] == goals, json.dumps(report)
    assert report['taken'] - report['proof_taken'] == report['own_received'] == goals * 6
    assert report['arrival_timeouts'] == 0
    if mode == 'client':
        assert report['updates'] == report['held_goals'] == 0
    else:
        assert report['updates'] < goals / 10, 'goals were not batched'
        assert report['held_goals'] > 0, json.dumps(report)


# --- in-process clients against a server process --------------------------------------------------

def make_client(ros, action, **kwargs):
    """A client whose goal service and feedback path are proven (tests.support.prove_feedback_path):
    its counters include that proof's goals, so a test counts from a snapshot."""
    client = ActionClient(ros.node, Fibonacci, action, **kwargs)
    assert client.wait_for_server(timeout_sec=20)
    prove_feedback_path(ros.spin_until, client)
    return client


@pytest.mark.parametrize('mode', ['client', 'goals', 'off'])
def test_feedback_published_before_the_result_but_taken_after_it_is_delivered(ros, mode):
    """Feedback, status and result travel on different topics, and rclpy takes one sample of each
    per wake: feedback still queued when the result is taken comes after it. Plain rclpy drops it,
    since it forgets the callback when the result arrives (measured by
    benchmarks/first_feedback.py, README "Differences from rclpy"; whether a plain client here
    has the result queued before its first wake depends on timing, so it is not asserted); this
    client delivers it, because the server stamped it before the result
    (tests/test_rclpy_contract.py has the converse)."""
    action = '/' + unique_name('fib')
    order = 5
    # 0.25 s apart, so that the goal is accepted long before its last feedback is published.
    child = start_server(action, period=0.25)
    try:
        client = make_client(ros, action, feedback_filter=mode)
        before = client.feedback_filter_state
        received = []  # (k, whether the result was in by then)
        result = Future()
        handle = send(ros, client, order, feedback_callback=lambda m: received.append(
            (m.feedback.sequence[0], result.done())))
        result = handle.get_result_async()
        # Not spinning: the goal's feedback and its result queue up in the client.
        deadline = time.monotonic() + 20
        while child.request_json('stats', 'STATS')['active'] and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)  # the result is sent once the executor has run the goal's end
        assert ros.spin_until(result.done, 20)
        assert result.result().status == GoalStatus.STATUS_SUCCEEDED
        ros.spin_until(lambda: len(received) == order, 5)
        ros.spin_for(0.3)
    finally:
        child.stop()
    assert [k for k, _ in received] == list(range(order))
    assert any(after for _, after in received), 'nothing was queued behind the result'
    state = client.feedback_filter_state
    assert (state.feedback_taken - state.feedback_dropped) - \
        (before.feedback_taken - before.feedback_dropped) == order


def test_default_mode_is_client_with_a_tag_and_a_fixed_filter(ros, server):
    action, _ = server
    client = make_client(ros, action)
    state = client.feedback_filter_state
    assert (state.mode, state.active, state.reason, state.updates) == ('client', True, '', 0)
    tag = client.new_goal_uuid().uuid[:4]
    assert state.expression == ' AND '.join(f'goal_id.uuid[{i}] = {b}' for i, b in enumerate(tag))
    generated = uuid.UUID(bytes=bytes(client.new_goal_uuid().uuid))
    assert generated.version == 4 and generated.variant == uuid.RFC_4122


def test_explicit_uuid_without_the_tag_still_gets_its_feedback(ros, server):
    action, _ = server
    client = make_client(ros, action)
    own = UUID(uuid=list(uuid.uuid4().bytes))
    received = []
    handle = send(ros, client, 5, feedback_callback=received.append, goal_uuid=own)
    assert result_of(ros, handle).status == GoalStatus.STATUS_SUCCEEDED
    ros.spin_until(lambda: len(received) == 5, 5)
    assert [m.feedback.sequence[0] for m in received] == list(range(5))
    assert all(bytes(m.goal_id.uuid) == bytes(own.uuid) for m in received)
    assert client.feedback_filter_state.updates == 1


@pytest.fixture(scope='module')
def slow_filter_updates(tmp_path_factory):
    """The environment of a guarded server whose writers process filter updates 0.5 s late.

    The shim (tests/helpers/slow_filter_updates.c) sleeps in the server's discovery thread, before
    the guard and Fast DDS see an update of a known reader: the way an update that lost the race
    against the goal request reaches the server, every time.
    """
    compiler = shutil.which('cc') or shutil.which('gcc')
    if compiler is None:
        pytest.skip('no C compiler to build the shim')
    shim = tmp_path_factory.mktemp('slow_filter_updates') / 'slow_filter_updates.so'
    subprocess.run([compiler, '-O2', '-shared', '-fPIC', '-o', str(shim),
                    str(Path(__file__).parent / 'helpers' / 'slow_filter_updates.c'), '-ldl'],
                   check=True, timeout=120, capture_output=True)
    env = guard.environment()
    env['LD_PRELOAD'] = f"{shim}:{env['LD_PRELOAD']}"
    env['SLOW_FILTER_UPDATES_MS'] = '500'
    return env


@pytest.mark.parametrize('mode', ['client', 'goals'])
def test_a_goal_is_held_until_its_filter_update_has_reached_the_server(
        ros, slow_filter_updates, mode):
    """A caller-supplied UUID that the filter does not match yet costs an update; the request is
    held until the server has it, so the feedback published in the first line of execute arrives.
    Without the hold, every such goal here lost its first feedback messages."""
    action = '/' + unique_name('fib')
    order = 3
    child = action_server(action, 0.1, env=slow_filter_updates)
    try:
        client = make_client(ros, action, feedback_filter=mode)
        held = client.feedback_filter_state.held_goals
        received: dict[bytes, list[int]] = {}
        for _ in range(3):
            own = UUID(uuid=list(uuid.uuid4().bytes))
            ks = received.setdefault(bytes(own.uuid), [])
            handle = send(ros, client, order, goal_uuid=own,
                          feedback_callback=lambda m, ks=ks: ks.append(m.feedback.sequence[0]))
            assert result_of(ros, handle).status == GoalStatus.STATUS_SUCCEEDED
        ros.spin_until(lambda: all(len(ks) == order for ks in received.values()), 5)
        assert child.poll() is None, f'server died\n{child.tail()}'
    finally:
        child.stop()
    assert list(received.values()) == [list(range(order))] * 3
    state = client.feedback_filter_state
    assert state.updates >= 3 and state.held_goals - held == 3, state
    assert state.confirmed and state.arrival_timeouts == 0, state


def test_a_held_goal_waits_from_the_first_spin_not_from_the_call(ros, server, monkeypatch):
    """A caller that sends goals and spins only later gives the probe no chance before: its wait
    counts from the executor's first poll, so a late spin does not make it give up."""
    # Shorter than the default to keep the test short, still far longer than a reply takes.
    monkeypatch.setattr(cft_action.action.client, 'FILTER_ARRIVAL_TIMEOUT', 3.0)
    action, _ = server
    client = make_client(ros, action)
    held = client.feedback_filter_state.held_goals
    received = []
    future = client.send_goal_async(Fibonacci.Goal(order=3), feedback_callback=received.append,
                                    goal_uuid=UUID(uuid=list(uuid.uuid4().bytes)))
    time.sleep(3.5)  # not spinning: the probe cannot be polled, nor answered
    assert ros.spin_until(future.done, 20)
    assert result_of(ros, future.result()).status == GoalStatus.STATUS_SUCCEEDED
    ros.spin_until(lambda: len(received) == 3, 5)
    assert [m.feedback.sequence[0] for m in received] == [0, 1, 2]
    state = client.feedback_filter_state
    assert (state.held_goals - held, state.arrival_timeouts, state.confirmed) == (1, 0, True), state


def complete_feedback_of_one_goal(ros, client, order=3):
    """Send a goal with a feedback callback; return the ``k`` of its feedback, once finished."""
    received = []
    handle = send(ros, client, order, feedback_callback=received.append)
    assert result_of(ros, handle).status == GoalStatus.STATUS_SUCCEEDED
    ros.spin_until(lambda: len(received) == order, 5)
    return [m.feedback.sequence[0] for m in received]


@pytest.mark.parametrize('mode', ['client', 'goals'])
def test_the_first_goal_waits_for_proof_that_the_server_has_the_reader(ros, server, mode):
    """The feedback reader is recreated with the first filter, after the goal service's endpoints:
    a caller that only saw the server ready, without wait_for_server, has its first goal held
    until the server's cancel service proves that the feedback writer has the reader."""
    action, _ = server
    client = ActionClient(ros.node, Fibonacci, action, feedback_filter=mode)
    feedback_topic = f'{action}/_action/feedback'
    assert ros.spin_until(lambda: client.server_is_ready()
                          and ros.node.count_publishers(feedback_topic) > 0, 20)
    assert complete_feedback_of_one_goal(ros, client) == [0, 1, 2]
    assert client.feedback_filter_state.held_goals == 1, client.feedback_filter_state
    # Proven once: later goals are not held.
    assert complete_feedback_of_one_goal(ros, client, 1) == [0]
    assert client.feedback_filter_state.held_goals == 1, client.feedback_filter_state


def test_wait_for_server_proves_that_the_server_has_the_reader(ros, server):
    """wait_for_server returns once the server's services are there and its feedback writer is
    proven to have the reader, so the goals sent after it are never held."""
    action, _ = server
    client = ActionClient(ros.node, Fibonacci, action)
    assert client.wait_for_server(timeout_sec=20)
    assert complete_feedback_of_one_goal(ros, client) == [0, 1, 2]
    assert client.feedback_filter_state.held_goals == 0, client.feedback_filter_state


def test_goal_without_feedback_callback_receives_no_feedback(ros, server):
    action, _ = server
    client = make_client(ros, action)
    taken = client.feedback_filter_state.feedback_taken
    handle = send(ros, client, 5)
    assert result_of(ros, handle).status == GoalStatus.STATUS_SUCCEEDED
    ros.spin_for(0.3)
    assert client.feedback_filter_state.feedback_taken == taken


SHORT_GRACE = 1.0


def short_grace(monkeypatch):
    """Finished goals released after 1 s, not FINISHED_GOAL_GRACE: a test of the release itself."""
    monkeypatch.setattr(cft_action.action.client, 'FINISHED_GOAL_GRACE', SHORT_GRACE)
    monkeypatch.setattr(cft_action.action.client, 'RELEASE_CHECK_PERIOD', 0.2)


@pytest.mark.parametrize('mode', ['client', 'goals'])
def test_cancel_and_reject_behave_as_rclpy_and_release_callbacks(ros, server, mode, monkeypatch):
    action, _ = server
    short_grace(monkeypatch)
    client = make_client(ros, action, feedback_filter=mode)
    received = []
    rejected = send(ros, client, -1, feedback_callback=received.append)
    assert not rejected.accepted
    handle = send(ros, client, 10000, feedback_callback=received.append)
    assert handle.accepted
    assert ros.spin_until(lambda: len(received) >= 3, 10)
    cancel = handle.cancel_goal_async()
    assert ros.spin_until(cancel.done, 10)
    assert len(cancel.result().goals_canceling) == 1
    assert result_of(ros, handle).status == GoalStatus.STATUS_CANCELED
    # nobody asked for the rejected goal's result: its callback is released all the same
    assert ros.spin_until(lambda: not client._feedback_callbacks, SHORT_GRACE + 15)
    state = client.feedback_filter_state
    assert state.live_goals == 0
    if mode == 'goals':
        assert ros.spin_until(lambda: client.feedback_filter_state.live_goals == 0, 5)


def test_finished_goals_are_released_without_asking_for_results(ros, server, monkeypatch):
    """rclpy keeps feedback callbacks until the result is requested; finished goals leak there."""
    action, _ = server
    short_grace(monkeypatch)
    client = make_client(ros, action, feedback_filter='goals')
    handles = [send(ros, client, 2, feedback_callback=lambda m: None) for _ in range(20)]
    assert all(h.accepted for h in handles)
    assert ros.spin_until(lambda: all(h.status == GoalStatus.STATUS_SUCCEEDED for h in handles),
                          15)
    assert ros.spin_until(lambda: not client._feedback_callbacks, SHORT_GRACE + 15)
    assert ros.spin_until(lambda: client.feedback_filter_state.live_goals == 0, 5)
    state = client.feedback_filter_state
    assert state.active and state.updates <= 3


def test_goals_mode_starts_with_announced_reserve_and_never_empty(ros, server):
    action, _ = server
    client = make_client(ros, action, feedback_filter='goals')
    state = client.feedback_filter_state
    assert state.active and state.updates == 0
    assert state.expression and state.expression != NEVER_MATCH  # the reserve is announced
    received = []
    handle = send(ros, client, 3, feedback_callback=received.append)
    assert result_of(ros, handle).status == GoalStatus.STATUS_SUCCEEDED
    assert ros.spin_until(lambda: len(received) == 3, 5)
    assert client.feedback_filter_state.updates == 0


def test_destroy(ros, server):
    action, _ = server
    client = make_client(ros, action)
    handle = send(ros, client, 3, feedback_callback=lambda m: None)
    result_of(ros, handle)
    client.destroy()
    assert client not in list(ros.node.waitables)
    assert ros.node.count_subscribers(f'{action}/_action/feedback') == 0 or \
        ros.spin_until(lambda: ros.node.count_subscribers(f'{action}/_action/feedback') == 0, 5)


def test_multithreaded_executor_with_goals_sent_from_another_thread(server):
    action, server_proc = server
    ros = RosSession(MultiThreadedExecutor, num_threads=4)
    spinner = threading.Thread(target=ros.executor.spin, daemon=True)
    spinner.start()
    try:
        time.sleep(0.2)  # the executor is waiting when the client is created
        # 12 goal responses may arrive before this loaded executor takes one: rclpy's default depth
        # of 10 would drop the oldest, and their send_goal would wait for ever.
        deep = QoSProfile(depth=1000)
        client = ActionClient(ros.node, Fibonacci, action, feedback_filter='goals',
                              goal_service_qos_profile=deep, result_service_qos_profile=deep,
                              feedback_sub_qos_profile=deep)
        assert client.wait_for_server(timeout_sec=20)
        # send_goal waits for ever on a goal response that was lost: prove the service (and the
        # feedback path, which the test counts) first.
        assert round_trip(ros, client, wait=wait_until), server_evidence(server_proc)
        prove_feedback_path(wait_until, client)
        lock = threading.Lock()
        received: dict[int, list[int]] = {}

        def sender(index):
            def on_feedback(msg, index=index):
                with lock:
                    received.setdefault(index, []).append(msg.feedback.sequence[0])
            result = client.send_goal(Fibonacci.Goal(order=5), feedback_callback=on_feedback)
            assert result.status == GoalStatus.STATUS_SUCCEEDED

        threads = [threading.Thread(target=sender, args=(i,)) for i in range(12)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(timeout=30)
        assert not any(t.is_alive() for t in threads)
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and any(len(v) < 5 for v in received.values()):
            time.sleep(0.05)
        # A goal sent after its hold timed out (arrival_timeouts) may lose feedback by design.
        assert {i: sorted(v) for i, v in received.items()} == \
            {i: list(range(5)) for i in range(12)}, client.feedback_filter_state
        assert client.feedback_filter_state.active
    finally:
        ros.close()
        spinner.join(timeout=5)


def test_fallback_through_an_unavailable_binding(ros, server, monkeypatch):
    action, _ = server
    monkeypatch.setattr(cft_action._rcl, 'action_feedback_subscription',
                        lambda pointer, name: (None, 'layout check failed: forced by the test'))
    client = make_client(ros, action)
    state = client.feedback_filter_state
    assert not state.active and 'forced by the test' in state.reason and state.expression == ''
    dropped = state.feedback_dropped
    received = []
    handle = send(ros, client, 4, feedback_callback=received.append)
    # Without the binding, feedback is taken as by rclpy, and as there the feedback that arrives
    # after the goal's result is dropped (feedback and result race on different topics): so the
    # feedback is awaited before the result is asked for.
    assert ros.spin_until(lambda: len(received) == 4, 20), received
    assert result_of(ros, handle).status == GoalStatus.STATUS_SUCCEEDED
    assert client.feedback_filter_state.feedback_dropped == dropped


def test_mode_from_environment_and_bad_values(ros, server, monkeypatch):
    action, _ = server
    monkeypatch.setenv('CFT_ACTION_FEEDBACK_FILTER', 'off')
    assert make_client(ros, action, feedback_filter='goals').feedback_filter_state.mode == 'off'
    monkeypatch.setenv('CFT_ACTION_FEEDBACK_FILTER', 'everything')
    with pytest.raises(ValueError, match='CFT_ACTION_FEEDBACK_FILTER'):
        ActionClient(ros.node, Fibonacci, action)
    monkeypatch.delenv('CFT_ACTION_FEEDBACK_FILTER')
    with pytest.raises(ValueError, match="feedback_filter='sometimes'"):
        ActionClient(ros.node, Fibonacci, action, feedback_filter='sometimes')


@pytest.mark.parametrize('kwargs, mode', [
    ({'enable_feedback_msg_optimization': True}, 'client'),
    ({'enable_feedback_msg_optimization': False}, 'off'),
    ({'enable_feedback_msg_optimization': True, 'feedback_filter': 'goals'}, 'goals'),
])
def test_the_newer_distros_flag_is_accepted(ros, server, kwargs, mode):
    """Lyrical's rclpy names its opt-in filter enable_feedback_msg_optimization (rclpy#1633)."""
    action, _ = server
    assert make_client(ros, action, **kwargs).feedback_filter_state.mode == mode
    with pytest.raises(ValueError, match='contradicts'):
        ActionClient(ros.node, Fibonacci, action, enable_feedback_msg_optimization=False,
                     feedback_filter='client')


@pytest.mark.parametrize('mode', ['client', 'goals'])
def test_a_proof_that_never_comes_costs_a_client_one_hold(ros, mode, monkeypatch):
    """A server whose cancel service takes requests and never answers cannot prove that its
    feedback writer has this client's reader (nor a filter update in ``goals`` mode):
    wait_for_server waits for the proof once, for ``FILTER_ARRIVAL_TIMEOUT``, and every goal after
    it goes out at once, as plain rclpy's, where each goal used to wait that long again."""
    monkeypatch.setattr(cft_action.action.client, 'FILTER_ARRIVAL_TIMEOUT', 2.0)  # a shorter test
    action = '/' + unique_name('fib')
    child = action_server(action, PERIOD, env=guard.environment(), mute_cancel=True)
    try:
        client = ActionClient(ros.node, Fibonacci, action, feedback_filter=mode)
        started = time.monotonic()
        assert client.wait_for_server(timeout_sec=20)
        waited = time.monotonic() - started
        state = client.feedback_filter_state
        assert (state.arrival_timeouts, state.holds_suspended) == (1, True), state
        plain = RclpyActionClient(ros.node, Fibonacci, action)
        assert plain.wait_for_server(timeout_sec=20)
        latencies = {'plain': [], mode: []}
        feedback: list[list[int]] = []
        for _ in range(4):
            for name, each in (('plain', plain), (mode, client)):
                received: list[int] = []
                sent = time.monotonic()
                handle = send(ros, each, 3, feedback_callback=lambda m, r=received: r.append(
                    m.feedback.sequence[0]))
                latencies[name].append(round(time.monotonic() - sent, 3))
                assert result_of(ros, handle).status == GoalStatus.STATUS_SUCCEEDED
                if each is client:
                    feedback.append(received)
        stats = child.request_json('stats', 'STATS')
        assert child.poll() is None, f'server died\n{child.tail()}'
    finally:
        child.stop()
    state = client.feedback_filter_state
    evidence = f'waited {waited:.2f} s, latencies {latencies}, {state}, {stats}'
    assert stats['cancel_requests_unanswered'] > 0, evidence
    # No goal waited for the proof again: none was held, and each was answered as fast as a
    # plain client's, within the noise of a shared machine, far below the 2 s of a hold.
    assert (state.held_goals, state.arrival_timeouts, state.holds_suspended) == (0, 1, True), \
        evidence
    assert max(latencies[mode]) < 1.0, evidence
    assert 1.5 < waited < 10, evidence
