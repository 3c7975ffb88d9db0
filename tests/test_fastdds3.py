# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Fast DDS 3 (Kilted's wheels, Fast DDS 3.2.2): what the library does where no 2.14 layout applies.

``make test-kilted`` runs this file with the others that apply there (the Makefile's
``KILTED_TESTS``); on Jazzy's stack it is skipped.

- The library's own filter classes read Fast DDS 2.14 layouts: a default client says why it cannot
  use them, once, and is plain rclpy (every goal's feedback whole, ``filtered_in == 'none'``).
- Under the guard, a DDS-SQL client (``writer_filtering='any'``) is filtered by the server's
  writer: each filtered client's port receives exactly its own goals' feedback DATA, a plain one
  every goal's. The guard's Fast DDS 3 layer (tests/test_fastdds3_replies.py) is on where it is
  built for the stack, else off and says why (Kilted's 3.2.2 has no sample prefilter).
- Fast-DDS#4878 on 3.2: a guarded server and a client that changes its DDS-SQL filter 1,000 times at
  a 0.5 ms feedback period both survive (the guard locks the writer's filter changes against its
  writes; the reader lock serializes the client's own evaluations with the changes). Unguarded, the
  same server died after 134 and after 35 updates (docs/SAFETY.md, the command there). The other
  path, a filtered reader going away (``remove_reader_filter``, which 3.x locks itself), does not
  deadlock against the guard's lock: 30 DDS-SQL clients created and destroyed at that period.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

from cft_action import _rcl
from harness.capture import data_by_port
from harness.ros import unique_name
from tests.support import feedback_on_the_wire
from tests.test_action_client import run_clients, start_server
from tests.test_fastdds3_replies import MISSING as LAYER_MISSING
from tests.test_guard import hazard_cell


def _fast_dds_3() -> bool:
    lib = Path(sys.prefix) / 'lib'
    return any(lib.glob('libfastdds.so.3*')) and not any(lib.glob('libfastrtps.so.2*'))


pytestmark = pytest.mark.skipif(not _fast_dds_3(), reason='a Fast DDS 3 stack (Kilted\'s wheels)')
GOALS, ORDER = 2, 20


def test_the_reader_lock_is_installed(ros) -> None:
    assert _rcl.reader_lock_status() == ''


def test_a_default_client_says_why_it_has_no_filter_and_where_feedback_is_filtered() -> None:
    """The library's filter class is Fast DDS 2.14's: the client says so. Against this guarded
    server it is plain rclpy where the Fast DDS 3 layers are not built (Kilted's 3.2), and asks for
    its own goals' feedback, which the writer then filters, where they are (3.3+)."""
    action = '/' + unique_name('fib3')
    child = start_server(action)
    try:
        [report] = run_clients(child, action, 'client', 1, GOALS, 5)
        assert child.poll() is None, f'server died\n{child.tail()}'
    finally:
        child.stop()
    assert not report['active'] and 'Fast DDS 2.14' in report['reason'], report
    assert report['filtered_in'] == ('writer' if LAYER_MISSING is None else 'none'), report
    assert report['complete_goals'] == GOALS and report['misrouted'] == 0, report


@pytest.mark.skipif(os.geteuid() != 0, reason='a raw socket needs root')
def test_a_guarded_server_filters_dds_sql_feedback_in_its_writer() -> None:
    run = feedback_on_the_wire([('client', 'any'), ('client', 'any'), ('rclpy', 'guarded')],
                               data_by_port, GOALS, ORDER)
    for report in run.reports:
        assert report['complete_goals'] == GOALS and report['misrouted'] == 0, report
    for report in run.reports[:2]:
        assert report['active'] and report['filtered_in'] == 'writer', report
    every = GOALS * ORDER * len(run.reports)
    assert sorted(len(samples) for samples in run.captured.values()) == (
        [GOALS * ORDER] * 2 + [every]), {p: len(s) for p, s in run.captured.items()}
    # The guard's Fast DDS 3 layer (replies): on where built for this stack, else off, and why.
    state = run.stats_after['guard_prefilter']
    assert state.startswith('on: ' if LAYER_MISSING is None else 'off: '), (state, LAYER_MISSING)


def test_the_guarded_server_and_a_churning_dds_sql_client_survive_1000_updates(
        monkeypatch) -> None:
    monkeypatch.setenv('CFT_ACTION_WRITER_FILTERING', 'any')
    outcome = hazard_cell('update', guarded=True, bound=1000)
    dump = json.dumps(outcome, indent=1)
    assert 'error' not in outcome, dump
    assert (outcome['guard_status'] or '').startswith('active: libfastdds.so.3'), dump
    assert outcome['survived'] and outcome['events'] == 1000, dump
    assert outcome['server'] == 'alive' and 'server_at_stop' not in outcome, dump
    assert outcome['guard_calls']['process_reader_filter_info'] >= 1000, dump
    assert not any('inactive' in line for line in outcome['guard_messages']), dump


def test_filtered_readers_that_go_away_neither_crash_nor_hang_a_guarded_server(
        monkeypatch) -> None:
    monkeypatch.setenv('CFT_ACTION_WRITER_FILTERING', 'any')
    outcome = hazard_cell('destroy', guarded=True, bound=30, settle=0.3)
    dump = json.dumps(outcome, indent=1)
    assert 'error' not in outcome and outcome['survived'] and outcome['events'] == 30, dump
    assert outcome['server'] == 'alive' and 'server_at_stop' not in outcome, dump
    assert outcome['guard_calls']['remove_reader_filter'] >= 30, dump
