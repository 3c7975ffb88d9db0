"""The differential soak end to end, tiny: plain rclpy, then both cft modes, one guarded server.

One run of ``benchmarks/differential.py`` (3 slots, 5 s of plain rclpy, then the same lives in
``client`` and ``goals`` mode), in a process of its own with the session's ROS domain. It checks
the shape of the report and that no configuration saw a foreign message; the comparison with
plain rclpy is the benchmark's to report, not this test's to pass or fail (plain rclpy loses
feedback too on a loaded machine).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ('rclpy', 'client', 'goals')


@pytest.fixture(scope='module')
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp('differential') / 'report.json'
    command = [sys.executable, '-m', 'benchmarks.differential', '--duration', '2', '--slots', '2',
               '--seed', '12', '--linger', '1', '--domain', os.environ['ROS_DOMAIN_ID'],
               '--out', str(out), '--markdown']
    run = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=150)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    return json.loads(out.read_text()), run.stdout


def test_the_report_has_every_config_and_the_run_facts(report):
    result, stdout = report
    header = result['header']
    assert header['command'].startswith('python -m benchmarks.differential')
    assert header['date_utc'] and 'CPUs' in header['machine']
    assert list(result['summaries']) == list(CONFIGS)
    assert result['guard_status'].startswith('active'), result['guard_status']
    assert '| config |' in stdout and '| ratio to plain |' in stdout
    plain = result['summaries']['rclpy']
    assert plain['goals'] > 0 and plain['goals_cb'] > 0 and plain['delivered'] > 0
    for config in ('client', 'goals'):
        s = result['summaries'][config]
        # The same seeded lives as plain: every goal has its counterpart.
        assert s['lives'] == plain['lives'], (config, s['lives'], plain['lives'])
        assert s['goals_not_in_plain'] == 0
        for key in ('comparable', 'fewer_than_plain', 'fewer_first_after_update', 'fewer_at_start',
                    'fewer_gaps', 'lost', 'published_cb', 'server_crashes', 'ratio_to_plain'):
            assert key in s, key
        assert s['fewer_than_plain'] == (s['fewer_first_after_update'] + s['fewer_at_start']
                                         + s['fewer_gaps'])
        assert s['filters_inactive'] == 0


def test_no_configuration_sees_a_foreign_message(report):
    result, _ = report
    for config, s in result['summaries'].items():
        assert s['foreign_cb'] == 0, config
        assert s['foreign'] == 0, (config, s)
    assert result['summaries']['rclpy']['taken_other'] > 0  # plain takes everyone's feedback
    assert not result['crashes']
