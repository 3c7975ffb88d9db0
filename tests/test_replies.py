"""Replies on the wire: under the guard, each goal, cancel and result reply goes only to the
participant whose request it answers (cft_action/native/guard/_guard_replies.c).

rmw_fastrtps writes every reply to every client's response reader, and each client's take discards
the others'. A guarded server's reply writers send a reply only to the readers of the requesting
participant (the reply's related sample identity); the other readers get a GAP for it. Here a server
with 100 kB results serves three clients of the library, one per feedback filter mode, and a plain
rclpy client, each in its own process and with its own number of goals, on UDP only; a raw socket
on loopback (root) reads the reply writers' DATA and bytes by destination port, one port per
client's participant (:func:`harness.capture.samples_by_port`).
"""

from __future__ import annotations

import os
from typing import Optional, Sequence

import pytest

from harness.capture import PortTraffic, samples_by_port
from tests.support import clients_on_the_wire, WireRun

#: (feedback filter mode, or ``rclpy`` for a plain client; goals), one client process each.
CLIENTS = (('client', 1), ('goals', 2), ('off', 3), ('rclpy', 4))
ORDER = 2
#: int32 elements in each result: 100 kB.
RESULT_PAD = 25_000
RESULT_BYTES = 4 * RESULT_PAD
#: 10 kB: every result goes to every client, and less is enough to show it.
UNGUARDED_RESULT_PAD = 2_500
REPLY_WRITERS = ('send_goal', 'cancel_goal', 'get_result')
pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason='a raw socket needs root')


def replies_on_the_wire(guarded: bool, clients: Sequence[tuple[str, int]] = CLIENTS,
                        result_pad: int = RESULT_PAD,
                        server_env: Optional[dict[str, str]] = None) -> WireRun:
    """Run the server (guarded or not, with ``server_env`` added) and one client process per
    (mode, goals) of ``clients``, started together, capturing what each port received from the
    reply writers while their goals ran (benchmarks/replies.py measures with it too)."""
    return clients_on_the_wire([(mode, goals, ORDER) for mode, goals in clients], samples_by_port,
                               REPLY_WRITERS, guarded=guarded, server_env=server_env,
                               result_pad=result_pad, together=True)


def ports(run: WireRun) -> dict[int, PortTraffic]:
    """What each port received from the reply writers."""
    return run.captured


def assert_every_goal_completed(run: WireRun) -> None:
    """Every goal got its result, and each of the library's clients every feedback of its goals.

    A plain rclpy client drops a goal's feedback callback once its result is taken, so a lagging
    one may miss a goal's last feedback (measured here under load): of its feedback, only that
    none is another's is asserted."""
    for (mode, goals), report in zip(CLIENTS, run.reports):
        assert report['results'] == goals and report['misrouted'] == 0, (mode, report)
        if mode != 'rclpy':
            assert report['complete_goals'] == goals, (mode, report)


def results_per_port(run: WireRun) -> dict[int, int]:
    """The result samples each port received."""
    results = bytes.fromhex(run.stats_at_go['writers']['get_result'][0])
    return {port: sum(writer == results for writer, _ in seen.samples)
            for port, seen in ports(run).items()}


def assert_each_port_received_only_its_own(run: WireRun,
                                           clients: Sequence[tuple[str, int]]) -> None:
    """No reply reached two participants, each client's port received its own goals' results and,
    in bytes, about no more, no reply DATA carried a filter signature, and the guard routed the
    action's three reply writers, withholding some replies and finding every identity plausible."""
    samples = [set(seen.samples) for seen in ports(run).values()]
    assert len(samples) == len(clients), ports(run).keys()
    assert len(set().union(*samples)) == sum(map(len, samples)), 'a reply reached two clients'
    per_port = results_per_port(run)
    assert sorted(per_port.values()) == sorted(goals for _, goals in clients), per_port
    for port, seen in ports(run).items():
        # Besides its results, a port gets its goal replies, GAPs and heartbeats (a few kB), and
        # repairs of its own samples after a loss, which are not counted here.
        own, got = per_port[port] * RESULT_BYTES, seen.octets - seen.resent_octets
        assert own <= got < own + RESULT_BYTES // 4, (port, seen, own)
        assert set(seen.samples.values()) == {None}, 'a reply carried a filter signature'
    replies = run.stats_after['guard_replies']
    assert replies['marked'] == len(REPLY_WRITERS) and replies['withheld'] > 0, replies
    assert replies['implausible'] == replies['full'] == 0, replies


def test_each_client_receives_only_its_own_replies() -> None:
    """Under the guard: no reply reaches two participants, each client's results are its own
    goals', in bytes too, no reply DATA carries a filter signature, the library's clients drop no
    other client's reply (their response filter's ``dropped`` is 0), and every goal completes, for
    each mode and for the plain client."""
    run = replies_on_the_wire(guarded=True)
    assert_every_goal_completed(run)
    for (mode, _), report in zip(CLIENTS, run.reports):
        if mode != 'rclpy':
            assert report['responses_dropped'] == 0 < report['responses_passed'], (mode, report)
    assert_each_port_received_only_its_own(run, CLIENTS)


def test_an_unguarded_server_sends_every_reply_to_every_client() -> None:
    """Without the guard nothing changes: every client's participant receives every reply, all
    the results' bytes, and the library's clients drop the others' replies themselves."""
    run = replies_on_the_wire(guarded=False, result_pad=UNGUARDED_RESULT_PAD)
    assert_every_goal_completed(run)
    samples = [set(seen.samples) for seen in ports(run).values()]
    assert len(samples) == len(CLIENTS) and all(s == samples[0] for s in samples), ports(run).keys()
    every = sum(goals for _, goals in CLIENTS)
    assert set(results_per_port(run).values()) == {every}
    assert min(seen.octets - seen.resent_octets for seen in ports(run).values()) >= (
        every * 4 * UNGUARDED_RESULT_PAD)
    for (mode, goals), report in zip(CLIENTS, run.reports):
        if mode != 'rclpy':
            assert report['responses_dropped'] >= 2 * (every - goals), (mode, report)
    assert run.stats_after['guard_replies'] == {}
