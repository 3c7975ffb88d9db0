# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""One client, many concurrent goals, against the C server: what the client pays per goal.

Usage: ``python -m benchmarks.c_server_goals [--goals 2000] [--order 4] [--period 2.0]
[--configs client,rclpy] [--out FILE]``, or ``--markdown JSON`` to print the table again.

``benchmarks/many_goals.py`` runs against rclpy's ``ActionServer``, which spends most of the run's
CPU itself (goal acceptance, status arrays converted to Python), so its figures say little about
the client. Here the server is :mod:`harness.c_server`'s (``rcl_action`` in C, a thread per goal,
under the guard, ``--hold-goals GOALS`` so that all goals are live at once), and for each
configuration (``client``: :class:`cft_action.ActionClient` in its default mode; ``rclpy``: plain
:class:`rclpy.action.ActionClient`) a fresh server and one :mod:`harness.client` process, which
sends GOALS goals of ORDER feedback messages at once. Measured from ``go`` until the server
finished every goal and the client took everything: the client's CPU (user + system) per goal,
the feedback delivered to callbacks against what was published, and the status the client took.

Status is the protocol's: every ``GoalStatusArray`` lists every goal the server holds (finished
ones until the result timeout), and one is published at every transition of any goal, so a run of
G goals publishes O(G) arrays of O(G) entries: O(G²) bytes. The table gives the status samples the
client took (its status reader keeps the last sample only, so a slow client takes fewer), the goal
entries they listed and their size, and how many entries were converted to Python (the library's
status trim converts its own goals' changes only).
Results go to ``benchmarks/results/c-server-goals-<date>-<host>.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any, Callable, Optional, Sequence

from cft_action import guard
from harness import c_server, load
from harness.cli import name_list
from harness.domain import unused_domain
from harness.proc import Proc, python_module
from harness.report import (add_results_arguments, fmt, grid, markdown_only, markdown_table,
                            results_start, say)
from harness.status_model import status_array_size

CONFIGS = ('client', 'rclpy')
#: Seconds without a new callback that end a phase.
QUIET_S = 4.0
LABELS = {'client': 'cft_action (default mode)', 'rclpy': 'plain rclpy'}


def run_phase(config: str, args: argparse.Namespace) -> dict[str, Any]:
    """A fresh guarded C server and one client process of ``config``; the raw figures."""
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    env['ROS_DOMAIN_ID'] = os.environ.get('CFT_LOAD_DOMAIN_ID') or str(unused_domain())
    env.pop('CFT_ACTION_FEEDBACK_FILTER', None)
    depth = max(1000, args.goals * args.order + 100)
    action = f'/cft_c_goals_{os.urandom(4).hex()}'
    server = c_server.start(action, args.period, env=guard.environment(env), depth=str(depth),
                            hold_goals=args.goals)
    client: Optional[Proc] = None
    try:
        client = Proc(config, python_module('harness.client', action, config, args.goals,
                                            args.order, depth), env)
        client.expect('READY', 120)
        before = server.stats()
        go = time.monotonic()
        client.send('go')
        deadline = go + args.timeout
        while True:
            stats = server.stats(60)
            accepted = stats['accepted'] - before['accepted']
            if accepted >= args.goals and stats['active'] == 0:
                break
            if time.monotonic() > deadline:
                raise RuntimeError(f'{config}: the goals did not finish in {args.timeout} s: '
                                   f'{stats}')
            time.sleep(0.5)
        done_s = time.monotonic() - go
        # Quiet for longer than Fast DDS's periodic heartbeat (3 s): a sample lost in a burst (the
        # library's client takes 10,000 goals' feedback in 20 s) is repaired after the next one.
        load.wait_for_quiet([client], time.monotonic(), QUIET_S, args.timeout, say)
        window_s = time.monotonic() - go
        after = server.stats(60)
        report = client.request_json('report', 'RESULT', 120)
    finally:
        if client is not None:
            client.stop()
        server.stop()
    report.pop('latency_us', None)
    return {'config': config, 'goals': args.goals, 'order': args.order, 'depth': depth,
            'done_s': done_s, 'window_s': window_s,
            'published': after['published'] - before['published'],
            'server_cpu_s': after['cpu_s'] - before['cpu_s'],
            'client_cpu_s': report['cpu_s'],
            'client_cpu_per_goal_ms': 1e3 * report['cpu_s'] / args.goals,
            'server_status': server.all('STATUS')[:1], 'report': report}


def status_samples(phase: dict[str, Any]) -> int:
    """Status samples the client took from rcl (the library's status trim reads them itself)."""
    report = phase['report']
    return report.get('status_samples_read') or report['status']


def status_listed(phase: dict[str, Any]) -> int:
    """Goal entries listed in the status samples the client took, converted to Python or not."""
    report = phase['report']
    return report.get('status_entries_listed') or report['status_entries']


def status_bytes(phase: dict[str, Any]) -> int:
    """The serialized size of those samples (:func:`harness.status_model.status_array_size` is
    linear in the entries past the first)."""
    samples, listed = status_samples(phase), status_listed(phase)
    per_entry = status_array_size(2) - status_array_size(1)
    return samples * (status_array_size(1) - per_entry) + per_entry * listed


def table_rows(phases: list[dict[str, Any]]) -> list[list[str]]:
    """Header and rows, one column per configuration, and the ratio to plain rclpy."""
    by = {p['config']: p for p in phases}
    configs = [c for c in CONFIGS if c in by]
    head = ['', *[LABELS[c] for c in configs]]
    plain = by.get('rclpy')
    both = plain is not None and 'client' in by

    def row(name: str, key: Any, spec: str = '.0f', ratio: bool = False) -> list[str]:
        cells = [fmt(key(by[c]), spec) for c in configs]
        if both:
            cells.append(fmt(key(by['client']) / key(plain), '.2f') + 'x'
                         if ratio and key(plain) else '')
        return [name, *cells]

    rows = [head + (['cft / plain'] if both else [])]
    rows += [row('goals accepted', lambda p: p['report']['accepted']),
             row('goals done (status)', lambda p: p['report']['goals_done']),
             row('feedback published', lambda p: p['published']),
             row('feedback to callbacks', lambda p: p['report']['callbacks']),
             row('foreign feedback taken', lambda p: p['report']['foreign']),
             row('client CPU s (go to end)', lambda p: p['client_cpu_s'], '.2f', True),
             row('client CPU ms per goal', lambda p: p['client_cpu_per_goal_ms'], '.2f', True),
             row('server CPU s', lambda p: p['server_cpu_s'], '.2f'),
             row('status samples taken', status_samples),
             row('goal entries they listed', status_listed),
             row('their CDR MB (listed x 28 B + headers)', lambda p: status_bytes(p) / 1e6,
                 '.1f', True),
             row('goal entries converted to Python', lambda p: p['report']['status_entries'],
                 '.0f', True),
             row('all goals done at the server, s', lambda p: p['done_s'], '.1f'),
             row('last feedback callback, s', lambda p: p['report']['last_callback_s'], '.1f')]
    return rows


def markdown(result: dict[str, Any]) -> str:
    machine = result['machine']
    rows = table_rows(result['phases'])
    return '\n'.join([f'`{result["command"]}`, {result["started"]}, {machine["host"]}: '
                      f'{machine["cpus"]} CPUs ({machine["cpu_model"]})', '',
                      *markdown_table(rows[0], rows[1:], ['---'] + ['---:'] * (len(rows[0]) - 1))])


#: The options: flag, type, default, help.
OPTIONS: tuple[tuple[str, Callable[[str], Any], Any, str], ...] = (
    ('--goals', int, 2000, 'concurrent goals of the one client'),
    ('--order', int, 4, 'feedback messages per goal'),
    ('--period', float, 2.0, 'feedback period, s'),
    ('--configs', name_list(CONFIGS), list(CONFIGS), 'the clients, one phase each'),
    ('--timeout', float, 600.0, 'seconds a phase may take'),
)


def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    for flag, kind, default, text in OPTIONS:
        parser.add_argument(flag, type=kind, default=default, help=text)
    add_results_arguments(parser)
    return parser.parse_args(argv)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run each configuration's phase, write the results after each, and print the table."""
    args = parse_args(argv)
    if markdown_only(args, markdown):
        return 0
    output, header = results_start('c_server_goals', args.out, argv)
    result: dict[str, Any] = {**header, 'phases': []}
    c_server.build()
    for config in args.configs:
        say(f'{LABELS[config]}: {args.goals} goals of {args.order} feedback')
        result['phases'].append(run_phase(config, args))
        phase = result['phases'][-1]
        say(f'  client {phase["client_cpu_s"]:.2f} s CPU, '
            f'{phase["client_cpu_per_goal_ms"]:.2f} ms per goal; done at {phase["done_s"]:.1f} s')
        output.parent.mkdir(parents=True, exist_ok=True)
        output.write_text(json.dumps(result, indent=1))
    print(grid(table_rows(result['phases'])))
    print(f'results: {output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
