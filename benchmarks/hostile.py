# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""What hostile readers cost a server, guarded and not: the readers of tests/test_hostile.py's
hostile participant (tests/helpers/hostile_reader.cpp), against :mod:`harness.server`.

- ``memory``: a server per guard mode and spec set; the participant churns ``--readers`` readers
  of the set's specs (20 alive, 10 ms apart, as the test does), and the server's RSS
  (``/proc/<pid>/status`` VmRSS) is read after each ``--chunk`` of them, 2 s after the chunk.
  Sets: ``churn`` (the test's churned specs), ``oversize`` (the expression past 64 kB, which the
  test does not churn), ``plain`` (readers without a filter).
- ``cpu``: a server per guard mode publishing feedback every ``--period`` to a plain client's
  goals; phase by phase, ``--count`` resident readers of one spec (or none: ``baseline``), then
  the client's goals; the server's user + system CPU per feedback message over the goals, as a
  ratio to the baseline phase of the same server.

::

    python -m benchmarks.hostile memory --readers 2500 --chunk 300
    python -m benchmarks.hostile cpu --count 20

Results go to ``benchmarks/results/hostile-<measure>-<date>-<host>.json``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

from harness.domain import unused_domain

os.environ.setdefault('ROS_DOMAIN_ID', str(unused_domain()))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from cft_action import guard
from harness.machine import environment_facts
from harness.ros import unique_name
from tests.support import action_server, helper_process
from tests.test_hostile import (CHURN_PAUSE_MS, CHURN_WINDOW, HOSTILE, PLAIN, Hostile, build,
                                rss_kb, start)

REPO = Path(__file__).resolve().parent.parent
GUARDS = ('on', 'off')
SETS = {'churn': [h for h in HOSTILE if h.name.startswith('h')],
        'oversize': [h for h in HOSTILE if h.name.startswith('x')],
        'plain': [h for h in PLAIN if h.topic == 'feedback']}
CPU_SPECS = ('baseline', 'plain_feedback', 'h_uuid_index', 'h_uuid_64k_kept', 'h_sql_range',
             'h_sql_params')


def server_env(guarded: bool) -> dict[str, str]:
    env = os.environ.copy()
    return guard.environment(env) if guarded else env


def memory(program: Path, specs: list[Hostile], guarded: bool, opts: argparse.Namespace
           ) -> list[tuple[int, int]]:
    """(readers churned, server RSS in kB) after each chunk."""
    action = '/' + unique_name('cft_hostile_memory')
    server = action_server(action, 0.01, env=server_env(guarded))
    hostile = None
    try:
        hostile = start(program, action, specs)
        prefix = os.path.commonprefix([spec.name for spec in specs])
        points, churned = [], 0
        while churned < opts.readers:
            count = min(opts.chunk, opts.readers - churned)
            hostile.request(f'churn {count} {CHURN_WINDOW} {CHURN_PAUSE_MS} {prefix}', 'CHURNED',
                            600)
            churned += count
            time.sleep(2.0)
            points.append((churned, rss_kb(server.pid)))
            print(f'    {churned} readers: {points[-1][1]} kB', flush=True)
        return points
    finally:
        if hostile is not None:
            hostile.stop()
        server.stop()


def cpu(program: Path, guarded: bool, opts: argparse.Namespace) -> dict[str, dict[str, float]]:
    """Per spec: the server's CPU ms per feedback message and messages/s over the client's goals."""
    action = '/' + unique_name('cft_hostile_cpu')
    server = action_server(action, opts.period, env=server_env(guarded))
    hostile = client = None
    phases: dict[str, dict[str, float]] = {}
    try:
        hostile = start(program, action, HOSTILE + PLAIN)
        client = helper_process('tests.helpers.fib_client', [action, 'rclpy', 1, opts.order],
                                timeout=90)
        for n, name in enumerate(CPU_SPECS):
            readers = [f'{name}_{n}_{i}' for i in range(opts.count if name != 'baseline' else 0)]
            for reader in readers:
                hostile.request(f'open {name} {reader}', 'OPENED', 30)
            time.sleep(3.0)  # discovery
            before = server.request_json('stats', 'STATS')
            client.send('go')
            client.expect('RESULT', 120)
            after = server.request_json('stats', 'STATS')
            for reader in readers:
                hostile.request(f'close {reader}', 'CLOSED', 30)
            messages = after['published'] - before['published']
            seconds = after['t'] - before['t']
            phases[name] = {'messages': messages,
                            'cpu_ms_per_msg': 1000 * (after['cpu_s'] - before['cpu_s']) / messages,
                            'msgs_per_s': messages / seconds}
            print(f'    {name}: {phases[name]}', flush=True)
            client.stop()
            client = helper_process('tests.helpers.fib_client', [action, 'rclpy', 1, opts.order],
                                    timeout=90)
        return phases
    finally:
        for process in (client, hostile, server):
            if process is not None:
                process.stop()


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('measure', choices=['memory', 'cpu'])
    parser.add_argument('--guards', default=','.join(GUARDS))
    parser.add_argument('--sets', default=','.join(SETS), help='memory: the spec sets')
    parser.add_argument('--readers', type=int, default=2500, help='memory: readers churned')
    parser.add_argument('--chunk', type=int, default=300, help='memory: RSS read every so many')
    parser.add_argument('--count', type=int, default=20, help='cpu: resident readers a phase')
    parser.add_argument('--period', type=float, default=0.001, help='cpu: feedback period, s')
    parser.add_argument('--order', type=int, default=3000, help='cpu: feedback messages a goal')
    opts = parser.parse_args(argv)
    program = build()
    started = datetime.datetime.now(datetime.timezone.utc)
    header: dict[str, Any] = {
        'date_utc': f'{started:%Y-%m-%d %H:%M}', 'machine': environment_facts(),
        'command': 'python -m benchmarks.hostile ' + ' '.join(argv),
        'load_average_at_start': os.getloadavg()}
    print(json.dumps({k: header[k] for k in ('date_utc', 'command')}), flush=True)
    rows: list[dict[str, Any]] = []
    for guarded in (g == 'on' for g in opts.guards.split(',')):
        if opts.measure == 'memory':
            for name in opts.sets.split(','):
                print(f'  guard {"on" if guarded else "off"}, {name}:', flush=True)
                rows.append({'guard': guarded, 'set': name,
                             'rss_kb': memory(program, SETS[name], guarded, opts)})
        else:
            print(f'  guard {"on" if guarded else "off"}:', flush=True)
            rows.append({'guard': guarded, 'phases': cpu(program, guarded, opts)})
    for row in rows:
        if opts.measure == 'memory':
            (n0, first), (n1, last) = row['rss_kb'][0], row['rss_kb'][-1]
            print(f'guard {"on " if row["guard"] else "off"} {row["set"]:<9} {first} kB after '
                  f'{n0}, {last} kB after {n1}: {last / first:.3f}x')
        else:
            base = row['phases']['baseline']['cpu_ms_per_msg']
            for name, phase in row['phases'].items():
                cost = phase['cpu_ms_per_msg']
                print(f'guard {"on " if row["guard"] else "off"} {name:<16} {cost:.3f} ms/msg '
                      f'({cost / base:.2f}x), {phase["msgs_per_s"]:.0f} msgs/s')
    out = REPO / 'benchmarks' / 'results' / \
        f'hostile-{opts.measure}-{started:%Y-%m-%d}-{platform.node()}.json'
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({**header, 'load_average_at_end': os.getloadavg(), 'rows': rows},
                              indent=1))
    print(f'results: {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
