# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The library's clients against servers as production runs them: the C server of
:mod:`harness.c_server`, several ``rcl_action`` servers in one process (an executor thread each)
and a thread per goal publishing feedback, every ``rcl_action`` call under a per-server recursive
mutex as ``rclcpp_action`` takes it. Unlike an rclpy server (which holds the GIL while it
publishes), its writers publish from many threads at once.

Every server runs under the guard (``cft_action.guard.environment()``), every client in the
library's default mode unless it is a plain rclpy one; the client processes are
``tests/helpers/fib_client.py`` (which waits for its goals' results and says which feedback each
got) and :mod:`harness.client` (which counts own and foreign feedback taken from rcl). The tests
skip, saying why, where the C server cannot be built (no C compiler, no ROS headers).
"""

from __future__ import annotations

import json
import os
import time
from typing import Any, Iterator, Sequence

import pytest

from cft_action import guard
from harness import c_server
from harness.proc import Proc, python_module, stop_all
from harness.ros import unique_name


@pytest.fixture(scope='module', autouse=True)
def built() -> None:
    """Build the C server once (cached), or skip the module with the reason."""
    try:
        c_server.build()
    except c_server.CServerUnavailable as error:
        pytest.skip(str(error))


@pytest.fixture
def procs() -> Iterator[list[Proc]]:
    """The processes a test starts; all stopped when it ends, pass or fail."""
    started: list[Proc] = []
    yield started
    stop_all(reversed(started))


def guarded_server(procs: list[Proc], period: float, servers: int, **env: str) -> c_server.CServer:
    """A guarded C server of ``servers`` actions with keep-all queues (as tests.support's
    action_server: nothing is dropped on a loaded machine), its guard active."""
    action = '/' + unique_name('cft_c')
    server = c_server.start(action, period, servers=servers, depth='all',
                            env=guard.environment({**os.environ, **env}))
    procs.append(server)
    assert server.all('STATUS True active'), server.tail()
    return server


def clients(procs: list[Proc], argvs: Sequence[list[str]], timeout: float = 60.0) -> list[Proc]:
    """Client processes started at once, then each waited for until ``READY``."""
    started = [Proc(argv[3], argv, os.environ.copy()) for argv in argvs]
    procs.extend(started)
    for proc in started:
        proc.expect('READY', timeout)
    return started


def fib_client(action: str, goals: int, order: int, mode: str = 'client',
               writer_filtering: str = 'guarded') -> list[str]:
    """tests/helpers/fib_client.py: proves its feedback path before READY; ``go`` sends the goals
    and waits for their results."""
    return python_module('tests.helpers.fib_client', action, mode, goals, order, writer_filtering)


def load_client(action: str, config: str, goals: int, order: int) -> list[str]:
    """:mod:`harness.client` with every queue 1000 deep; counts feedback taken from rcl."""
    return python_module('harness.client', action, config, goals, order, 1000)


def report(proc: Proc, timeout: float = 90.0) -> dict[str, Any]:
    """The ``RESULT`` of a client process."""
    return json.loads(proc.expect('RESULT', timeout).split(' ', 1)[1])


def progress_until(proc: Proc, done: Any, timeout: float) -> dict[str, Any]:
    """A :mod:`harness.client`'s ``PROGRESS``, polled until ``done(progress)`` or ``timeout``."""
    deadline = time.monotonic() + timeout
    while True:
        progress = proc.request_json('progress', 'PROGRESS')
        if done(progress) or time.monotonic() > deadline:
            return progress
        time.sleep(0.2)


def published(stats: dict[str, Any]) -> list[int]:
    """Feedback published per action of a C server's ``STATS``."""
    return [server['published'] for server in stats['servers']]


def test_writer_filtering_is_exact_under_concurrent_publishing(procs) -> None:
    """Two servers in one process, each with 2 filtered clients and a plain one, every goal in a
    thread of its own: each filtered client takes its own goals' feedback only, all of it, and
    every result; the plain client takes everything its server published; the guard's verdicts
    (the library's filter class, kept by the guard) came for every sample and filtered reader."""
    goals, order = 4, 20
    server = guarded_server(procs, 0.005, servers=2, CFT_GUARD_VERIFY='1')
    filtered = clients(procs, [fib_client(a, goals, order) for a in server.actions for _ in '12'])
    # Started once the filtered clients proved their feedback path: from here to `go` the server
    # publishes nothing, so what the plain clients take is the goals' feedback, all of it.
    plain = clients(procs, [load_client(a, 'rclpy', goals, order) for a in server.actions])
    before = server.stats()
    for proc in filtered + plain:
        proc.send('go')
    reports = [report(proc) for proc in filtered]
    per_server = 3 * goals * order
    # Goal responses and terminal status as taken from rcl, not rclpy's goal handles: a response
    # that arrives after its goal's terminal status leaves rclpy's handle non-terminal for good.
    plains = [progress_until(p, lambda r: r['own'] + r['foreign'] >= per_server and
                             r['goal_responses'] == r['terminal_listed'] == goals, timeout=30)
              for p in plain]
    after = server.stats()
    assert server.poll() is None, server.tail()

    assert [a - b for a, b in zip(published(after), published(before))] == [per_server] * 2, after
    for r in reports:
        assert r['active'], r['reason']
        assert r['results'] == goals, r
        assert r['complete_goals'] == goals, r  # every goal got k = 0 .. order-1, in order
        assert r['own_received'] == goals * order and r['misrouted'] == 0, r
        assert r['taken'] - r['proof_taken'] == goals * order, f'foreign feedback taken: {r}'
        assert r['dropped'] == 0, r
        assert r['filtered_in'] == 'writer', r
    for p in plains:
        assert p['own'] == goals * order and p['foreign'] == 2 * goals * order, p
        assert p['callbacks'] == goals * order, p
        assert p['goal_responses'] == p['terminal_listed'] == goals, p
    verdicts = {k: after['guard_filter'][k] - before['guard_filter'][k]
                for k in after['guard_filter']}
    # Each filtered client's feedback and status readers, on each server: kept by the guard.
    assert after['guard_filter']['kept'] == 8 and after['guard_filter']['left'] == 0, after
    # rcl_action's goal requests, taken through rmw_take_request: each one's requester recorded.
    status = after['guard_status']
    assert status['requests'] >= 2 * 2 * goals and status['implausible'] == 0, status
    assert status['verdicts'] > 0 and status['unknown'] == status['malformed'] == 0, status
    assert verdicts['relevance_verdicts'] >= 2 * 2 * per_server, verdicts
    assert after['guard_filter']['mismatches'] == 0, after
    assert server.stop() == 0, server.tail()


def test_compiled_verdicts_agree_with_fast_dds(procs) -> None:
    """Beside a default-mode client, a DDS-SQL one (``writer_filtering='any'``) on each of two
    servers, with ``CFT_GUARD_VERIFY=1``: every verdict the guard compiled from its expression was
    also asked of Fast DDS, and none disagreed, while both servers publish from goal threads."""
    goals, order = 3, 20
    server = guarded_server(procs, 0.005, servers=2, CFT_GUARD_VERIFY='1')
    argvs = [fib_client(a, goals, order, writer_filtering=w)
             for a in server.actions for w in ('guarded', 'any')]
    started = clients(procs, argvs)
    before = server.stats()
    for proc in started:
        proc.send('go')
    reports = [report(proc) for proc in started]
    after = server.stats()
    assert server.poll() is None, server.tail()
    for r in reports:
        assert r['results'] == goals and r['complete_goals'] == goals, r
        assert r['taken'] - r['proof_taken'] == goals * order, r
    counts = after['guard_filter']
    verified = counts['verified'] - before['guard_filter']['verified']
    assert counts['compiled'] >= 2, counts
    assert verified >= sum(published(after)) - sum(published(before)), counts
    assert counts['verified'] == counts['uuid_verdicts'] and counts['mismatches'] == 0, counts
    assert server.stop() == 0, server.tail()


def churn(procs: list[Proc], period: float, rounds: int, order: int,
          complete: bool) -> tuple[c_server.CServer, list[dict[str, Any]], list[dict[str, Any]]]:
    """Two guarded servers, a plain client on each with a long goal (its writer publishes all the
    time), and ``rounds`` rounds of a filtered client process per server, created and destroyed:
    with ``complete``, after its goals' results (their reports are returned), else in the middle
    of its goals (their last progress is returned). Returns the server, those reports and the
    plain clients' progress."""
    server = guarded_server(procs, period, servers=2)
    steady_order = int(60 / period)  # longer than the test: the server's end ends it
    steady = clients(procs, [load_client(a, 'rclpy', 1, steady_order) for a in server.actions])
    for proc in steady:
        proc.send('go')
    results = []
    for _ in range(rounds):
        if complete:
            round_clients = clients(procs, [fib_client(a, 2, order) for a in server.actions])
        else:
            round_clients = clients(procs, [load_client(a, 'client', 2, order)
                                            for a in server.actions])
        for proc in round_clients:
            proc.send('go')
        if complete:
            results += [report(proc) for proc in round_clients]
        else:
            results += [progress_until(p, lambda r: r['callbacks'] >= order // 10, timeout=20)
                        for p in round_clients]
        for proc in round_clients:  # destroyed while the steady goals publish
            assert proc.stop() == 0, proc.tail()
            procs.remove(proc)
    progress = [p.request_json('progress', 'PROGRESS') for p in steady]
    assert server.poll() is None, f'the server died\n{server.tail()}'
    return server, results, progress


def test_client_churn_while_goals_publish(procs) -> None:
    """Filtered client processes come and go, two rounds of one per server, while a plain
    client's goal publishes on each server: each gets exactly its own feedback and results."""
    order = 20
    server, reports, steady = churn(procs, 0.01, rounds=2, order=order, complete=True)
    for r in reports:
        assert r['active'], r['reason']
        assert r['results'] == 2 and r['complete_goals'] == 2, r
        assert r['taken'] - r['proof_taken'] == 2 * order and r['dropped'] == 0, r
    assert all(p['callbacks'] > 0 for p in steady), steady
    stats = server.stats()
    assert stats['guard_filter']['mismatches'] == 0, stats
    assert server.stop() == 0, server.tail()


def test_soak_at_a_1_ms_feedback_period(procs) -> None:
    """At a 1 ms feedback period on two servers, filtered clients destroyed in the middle of their
    goals, two rounds: the guarded server survives and keeps publishing, and no client took
    foreign feedback (the removal of a filtered reader during a publish is what crashes an
    unguarded server, Fast-DDS#4878)."""
    order = 2000  # 2 s a goal: each client is destroyed while its own goals publish too
    server, progress, steady = churn(procs, 0.001, rounds=2, order=order, complete=False)
    for p in progress:
        assert p['callbacks'] >= order // 10 and p['foreign'] == 0, p
    before = server.stats()
    time.sleep(0.3)
    after = server.stats()
    assert sum(published(after)) > sum(published(before)), 'the server stopped publishing'
    assert after['guard_calls']['process_reader_filter_info'] > 0, after
    assert all(p['callbacks'] > 0 for p in steady), steady
    assert server.stop() == 0, server.tail()
