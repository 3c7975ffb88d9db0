# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""What filtered clients cost a C action server, per feedback message, guarded and not.

Usage: ``python -m benchmarks.c_server [--servers 2] [--clients 3] [--goals 1] [--order 500]
[--period 0.01] [--sizes 36B,1k] [--guards unguarded,guarded] [--rounds 1] [--out FILE]``,
or ``--markdown JSON`` to print the table of saved results again.

The server is :mod:`harness.c_server`'s: ``--servers`` ``rcl_action`` servers in one process, an
executor thread each and a thread per goal, as production (C++) servers run. For each guard mode
(``unguarded``; ``guarded``: ``cft_action.guard.environment()``) and each feedback size, one server
process serves the phases of both client configurations in turn (``rclpy``: plain
:class:`rclpy.action.ActionClient`; ``client``: :class:`cft_action.ActionClient` in its default
mode), ``--rounds`` times, the plain phase first in odd rounds and last in even ones. A phase is
``--clients`` fresh :mod:`harness.client` processes per action, each sending ``--goals`` goals of
``--order`` feedback messages at ``--period``; it is measured from ``go`` until the server
finished every goal (its ``STATS``: feedback published, ``cpu_s``), then the clients are left to
take what is still on its way and report their CPU and what they took.

Figures per phase: the server's CPU per feedback message published (user + system of the whole
process over the window, in µs), the clients' CPU per own feedback message, and what they took
(own and foreign). The table gives them as ratios of the plain phases of the same server:
``filtered / plain``, per guard mode and size; and ``guarded / unguarded`` for each configuration.
Results (machine, date, command, every raw figure) go to
``benchmarks/results/c-server-<date>-<host>.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from typing import Any, Optional, Sequence

from cft_action import guard
from harness import c_server, load
from harness.cli import name_list
from harness.domain import unused_domain
from harness.proc import Proc, add_cpu_arguments, pinned, python_module, stop_all
from harness.report import (add_results_arguments, fmt, grid, markdown_only, markdown_table,
                            results_start, say)

#: int32 elements after the 3-element header: 36 B and 1 kB feedback messages.
SIZES = {'36B': 0, '1k': 250, '10k': 2500}
GUARDS = ('unguarded', 'guarded')
CONFIGS = ('rclpy', 'client')
LABELS = {'rclpy': 'plain rclpy', 'client': 'cft_action (default mode)'}


def run_phase(server: c_server.CServer, config: str, args: argparse.Namespace,
              env: dict[str, str]) -> dict[str, Any]:
    """One configuration's clients against ``server``: their figures and the server's."""
    depth = max(1000, len(server.actions) * args.clients * args.goals * args.order + 100)
    clients = [Proc(f'{config} {i}', pinned(args.client_cpus, python_module(
                        'harness.client', action, config, args.goals, args.order, depth)), env)
               for action in server.actions for i in range(args.clients)]
    try:
        for client in clients:
            client.expect('READY', 120)
        before = server.stats()
        go = time.monotonic()
        for client in clients:
            client.send('go')
        expected = len(clients) * args.goals
        deadline = go + 120 + 10 * args.order * args.period
        while True:
            done = server.stats()
            if done['accepted'] - before['accepted'] >= expected and done['active'] == 0:
                break
            if time.monotonic() > deadline:
                raise RuntimeError(f'the goals did not finish in time: {done}')
            time.sleep(0.2)
        goals_s = time.monotonic() - go
        load.wait_for_quiet(clients, time.monotonic(), settle_s=1.0, drain_timeout=120,
                            progress=say)
        reports = [c.request_json('report', 'RESULT') for c in clients]
    finally:
        stop_all(clients)
    if server.poll() is not None:
        raise RuntimeError(f'the server died\n{server.tail()}')
    published = done['published'] - before['published']
    own = sum(r['own'] for r in reports)
    client_cpu = sum(r['cpu_s'] for r in reports)
    server_cpu = done['cpu_s'] - before['cpu_s']
    return {'config': config, 'published': published, 'goals_s': goals_s,
            'server_cpu_s': server_cpu,
            'server_cpu_per_msg_us': 1e6 * server_cpu / published if published else None,
            'server_preempted_per_msg': ((done['preempted'] - before['preempted']) / published
                                         if published else None),
            'late_ticks': done['late_ticks'] - before['late_ticks'],
            'cancel_requests': done['cancel_requests'] - before['cancel_requests'],
            'own': own, 'foreign': sum(r['foreign'] for r in reports),
            'callbacks': sum(r['callbacks'] for r in reports),
            'client_cpu_s': client_cpu,
            'client_cpu_per_own_msg_us': 1e6 * client_cpu / own if own else None,
            'guard_filter': {k: v - before['guard_filter'].get(k, 0)
                             for k, v in done['guard_filter'].items()},
            'clients': [{k: r[k] for k in ('own', 'foreign', 'callbacks', 'cpu_s', 'goals_done',
                                            'active', 'reason')} for r in reports]}


def run_point(guard_mode: str, size: str, args: argparse.Namespace) -> dict[str, Any]:
    """One server process (guard mode, size): the phases of every configuration, every round."""
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    env['ROS_DOMAIN_ID'] = os.environ.get('CFT_LOAD_DOMAIN_ID') or str(unused_domain())
    env.pop('CFT_ACTION_FEEDBACK_FILTER', None)
    server_env = guard.environment(env) if guard_mode == 'guarded' else env
    action = f'/cft_c_bench_{os.urandom(4).hex()}'
    server = c_server.start(action, args.period, env=server_env, servers=args.servers,
                            pad=SIZES[size], depth='all', cpus=args.server_cpus)
    phases = []
    try:
        for round_number, config in load.round_order(CONFIGS, args.rounds):
            say(f'  {guard_mode}, {size}, round {round_number}: {LABELS[config]}')
            phase = run_phase(server, config, args, env)
            say(f'    server {fmt(phase["server_cpu_per_msg_us"], ".1f")} µs/msg over '
                f'{phase["published"]} messages; clients '
                f'{fmt(phase["client_cpu_per_own_msg_us"], ".0f")} µs per own message')
            phases.append({**phase, 'round': round_number})
            time.sleep(1.0)  # let discovery retire this phase's readers
        status = server.all('STATUS')
    finally:
        server.stop()
    return {'guard': guard_mode, 'size': size, 'feedback_bytes': load.feedback_size(SIZES[size]),
            'server_status': status[0] if status else '', 'phases': phases}


def mean_of(point: dict[str, Any], config: str, key: str) -> Optional[float]:
    """The mean of ``key`` over ``point``'s phases of ``config``."""
    values = [p[key] for p in point['phases'] if p['config'] == config and p.get(key) is not None]
    return statistics.fmean(values) if values else None


def ratio(value: Optional[float], reference: Optional[float]) -> Optional[float]:
    return None if value is None or not reference else value / reference


def table_rows(points: list[dict[str, Any]]) -> list[list[str]]:
    """Header and rows: per point, both configurations' CPU per message and their ratios."""
    rows = [['guard', 'size', 'server µs/msg plain', 'server µs/msg filtered',
             'server filtered/plain', 'preempted/msg plain', 'preempted/msg filtered',
             'client µs/own msg plain', 'client µs/own msg filtered',
             'client filtered/plain', 'foreign taken plain', 'foreign taken filtered']]
    for point in points:
        plain = mean_of(point, 'rclpy', 'server_cpu_per_msg_us')
        filtered = mean_of(point, 'client', 'server_cpu_per_msg_us')
        plain_client = mean_of(point, 'rclpy', 'client_cpu_per_own_msg_us')
        filtered_client = mean_of(point, 'client', 'client_cpu_per_own_msg_us')
        rows.append([point['guard'], point['size'], fmt(plain, '.1f'), fmt(filtered, '.1f'),
                     fmt(ratio(filtered, plain), '.2f'),
                     fmt(mean_of(point, 'rclpy', 'server_preempted_per_msg'), '.2f'),
                     fmt(mean_of(point, 'client', 'server_preempted_per_msg'), '.2f'),
                     fmt(plain_client, '.0f'),
                     fmt(filtered_client, '.0f'), fmt(ratio(filtered_client, plain_client), '.2f'),
                     fmt(mean_of(point, 'rclpy', 'foreign')),
                     fmt(mean_of(point, 'client', 'foreign'))])
    return rows


def guard_rows(points: list[dict[str, Any]]) -> list[list[str]]:
    """Header and rows: the server's CPU per message guarded / unguarded, per size and config."""
    rows = [['size', *[f'{LABELS[c]}: guarded/unguarded' for c in CONFIGS]]]
    for size in dict.fromkeys(p['size'] for p in points):
        by_guard = {p['guard']: p for p in points if p['size'] == size}
        if set(GUARDS) <= set(by_guard):
            rows.append([size, *[fmt(ratio(mean_of(by_guard['guarded'], c, 'server_cpu_per_msg_us'),
                                           mean_of(by_guard['unguarded'], c,
                                                   'server_cpu_per_msg_us')), '.2f')
                                 for c in CONFIGS]])
    return rows


def markdown(result: dict[str, Any]) -> str:
    """The result's tables in Markdown, under its command, date and machine."""
    machine = result['machine']
    lines = [f'`{result["command"]}`, {result["started"]}, {machine["host"]}: {machine["cpus"]} '
             f'CPUs ({machine["cpu_model"]}), {result["servers"]} servers in one process, '
             f'{result["clients"]} client processes per server, {result["goals"]} goal(s) each '
             f'of {result["order"]} feedback every {result["period"] * 1000:g} ms.', '']
    for rows in (table_rows(result['points']), guard_rows(result['points'])):
        if len(rows) > 1:
            lines += markdown_table(rows[0], rows[1:], ['---'] + ['---:'] * (len(rows[0]) - 1))
            lines.append('')
    return '\n'.join(lines)


def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--servers', type=int, default=2, help='action servers in the process')
    parser.add_argument('--clients', type=int, default=3, help='client processes per server')
    parser.add_argument('--goals', type=int, default=1, help='goals per client')
    parser.add_argument('--order', type=int, default=500, help='feedback messages per goal')
    parser.add_argument('--period', type=float, default=0.01, help='feedback period, s')
    parser.add_argument('--sizes', type=name_list(SIZES), default=['36B', '1k'])
    parser.add_argument('--guards', type=name_list(GUARDS), default=list(GUARDS))
    parser.add_argument('--rounds', type=int, default=1, help='phases of each configuration')
    add_cpu_arguments(parser)
    add_results_arguments(parser)
    return parser.parse_args(argv)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Build the C server, run each (guard, feedback size) point, write the results after each
    point, and print the tables."""
    args = parse_args(argv)
    if markdown_only(args, markdown):
        return 0
    output, header = results_start('c_server', args.out, argv)
    result: dict[str, Any] = {
        **header, 'servers': args.servers, 'clients': args.clients, 'goals': args.goals,
        'order': args.order, 'period': args.period, 'points': []}
    c_server.build()
    for guard_mode in args.guards:
        for size in args.sizes:
            say(f'{guard_mode} server, {size} feedback')
            result['points'].append(run_point(guard_mode, size, args))
            output.parent.mkdir(parents=True, exist_ok=True)
            output.write_text(json.dumps(result, indent=1))
    print(grid(table_rows(result['points'])))
    print(grid(guard_rows(result['points'])))
    print(f'results: {output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
