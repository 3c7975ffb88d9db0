# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Replies on the wire on Fast DDS 3.3+ (Lyrical's 3.6.2, `make compat-kilted`): under the guard,
each goal, cancel and result reply goes only to the participant whose request it answers, through
the writers' public sample prefilter (cft_action/native/guard/fastdds3/, _guard_endpoints.c).

As tests/test_replies.py does on Jazzy: a server with 100 kB results serves a client of the library
(plain rclpy on Fast DDS 3, which it says) and two plain rclpy clients, each in its own process with
its own number of goals, on UDP only; a raw socket on loopback (root) reads the reply writers' DATA
and bytes by destination port, one port per client's participant. The clients start after the
server's reply writers exist (late joiners), and each sends its goals while the others' run.
Skipped where the guard's Fast DDS 3 layer is not built (no Fast DDS 3.3+ headers: Jazzy, Kilted's
wheels).
"""

from __future__ import annotations

import ctypes
import os
from typing import Optional

import pytest

from cft_action._native import extension_path, GUARD_FASTDDS3_LIBRARY
from tests.test_replies import (assert_each_port_received_only_its_own, ports,
                                replies_on_the_wire, results_per_port)

#: (feedback filter mode, or ``rclpy`` for a plain client; goals), one client process each.
CLIENTS = (('client', 1), ('rclpy', 2), ('rclpy', 3))


def _layer_missing() -> Optional[str]:
    """Why the guard's Fast DDS 3 layer cannot run here, or None: it is built only against Fast DDS
    3.3+ headers, and needs the Fast DDS it was linked against (its soname) on this stack."""
    path = extension_path(GUARD_FASTDDS3_LIBRARY)
    if path is None:
        return ("the guard's Fast DDS 3 layer is built only against Fast DDS 3.3+ headers "
                "(Lyrical's: make compat-kilted)")
    try:
        ctypes.CDLL(path, mode=os.RTLD_LAZY | os.RTLD_LOCAL)
    except OSError as error:
        return f"the guard's Fast DDS 3 layer does not load on this stack: {error}"
    return None


MISSING = _layer_missing()
pytestmark = [
    pytest.mark.skipif(MISSING is not None, reason=MISSING or ''),
    pytest.mark.skipif(os.geteuid() != 0, reason='a raw socket needs root'),
]


def test_each_client_receives_only_its_own_replies() -> None:
    """No reply reaches two participants; each client's results are its own goals', in bytes
    too; no reply DATA carries a filter signature; every goal completes with no other client's
    feedback; the guard's layer is on and routed the action's three reply writers."""
    run = replies_on_the_wire(guarded=True, clients=CLIENTS)
    assert run.stats_after['guard_prefilter'].startswith('on: '), run.stats_after
    for (mode, goals), report in zip(CLIENTS, run.reports):
        assert report['results'] == goals and report['misrouted'] == 0, (mode, report)
    assert_each_port_received_only_its_own(run, CLIENTS)


def test_with_the_reply_filter_off_every_client_receives_every_reply() -> None:
    """CFT_GUARD_REPLIES=off: the guard leaves the reply writers as rmw_fastrtps made them (no
    prefilter), and every client's participant receives every reply, as without the guard."""
    run = replies_on_the_wire(guarded=True, clients=CLIENTS, result_pad=2_500,
                              server_env={'CFT_GUARD_REPLIES': 'off'})
    for (mode, goals), report in zip(CLIENTS, run.reports):
        assert report['results'] == goals and report['misrouted'] == 0, (mode, report)
    samples = [set(seen.samples) for seen in ports(run).values()]
    assert len(samples) == len(CLIENTS) and all(s == samples[0] for s in samples), ports(run)
    assert set(results_per_port(run).values()) == {sum(goals for _, goals in CLIENTS)}
    assert run.stats_after['guard_replies']['marked'] == 0, run.stats_after['guard_replies']
    # The layer is still on, for the feedback writer (CFT_GUARD_FEEDBACK).
    assert run.stats_after['guard_prefilter'].startswith('on: '), run.stats_after
