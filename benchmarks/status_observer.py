# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""An observer's status cost: one client with one goal beside busy plain clients, side by side.

Usage: ``python -m benchmarks.status_observer [--rounds 3] [--plain-clients 4] [--goals 128]
[--order 2] [--period 0.05] [--configs rclpy,client] [--servers unguarded,guarded] [--out FILE]``,
or ``--markdown RESULTS.json`` to print the table of a saved run again.

Issue 26's scenario. Per round and server kind, one fresh action server (:mod:`harness.server`,
rclpy's ``result_timeout`` of 900 s, so every goal stays listed in every status sample), one
observer client process per configuration (:mod:`harness.client`: ``rclpy`` is plain
:class:`rclpy.action.ActionClient`, ``client`` and ``goals`` are :class:`cft_action.ActionClient`
in that mode), each sending one goal, and ``--plain-clients`` plain client processes sending
``--goals`` goals each, all at ``go``. The observers run at the same time, so they receive the
same status samples: their CPU (user + system, from ``go`` until the server has accepted and
finished every goal and no client's counters moved for 1.5 s) is compared within the round, as a
ratio to the plain observer's, with the part of it that Fast DDS's threads spent (receiving,
whatever Python takes). Each observer also reports the status samples and goal entries
that reached Python (``take_data``'s ``status``), and the library's ``goal_status_state``: the
entries the samples listed, and those it converted; and its ``response_filter_state``: the other
clients' goal, cancel and result responses its readers dropped before they woke the executor.

Results (machine, date, command, load averages, every raw figure) go to
``benchmarks/results/status-observer-<date>-<host>.json``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Optional, Sequence

from harness import load
from harness.cli import name_list
from harness.crash import machine_line, plain_env
from harness.domain import unused_domain
from harness.machine import environment_facts
from harness.proc import guard_command, Proc, python_module, ROOT
from harness.report import fmt, markdown_table, say

#: Every queue of every client and of the server: room for all goals of a burst.
DEPTH = 1000

#: Seconds the goals of a round may take, and its drain after them.
GOALS_TIMEOUT_S = 600.0


def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    """The command line: the spec."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument('--plain-clients', type=int, default=4)
    parser.add_argument('--goals', type=int, default=128, help='goals per plain client')
    parser.add_argument('--order', type=int, default=2, help='feedback messages per goal')
    parser.add_argument('--period', type=float, default=0.5, help='feedback period, s')
    parser.add_argument('--configs', type=name_list(load.CONFIG_LABELS),
                        default=['rclpy', 'client'],
                        help='observer configurations, from: ' + ', '.join(load.CONFIG_LABELS))
    parser.add_argument('--servers', default='unguarded,guarded')
    parser.add_argument('--out', type=Path)
    parser.add_argument('--markdown', type=Path, help='print the table of this result file')
    args = parser.parse_args(argv)
    args.servers = [s for s in args.servers.split(',') if s]
    if set(args.servers) - {'unguarded', 'guarded'}:
        parser.error('--servers: unguarded, guarded')
    return args


def wait_for_goals(server: Proc, accepted: int, go: float) -> float:
    """Wait until the server accepted ``accepted`` goals in all and runs none; seconds since go.

    The server's counters, not the clients' goal handles: a plain handle whose goal response is
    taken after its goal's last status sample stays without status until a later sample.
    """
    shown = go
    while True:
        stats = server.request_json('stats', 'STATS')
        now = time.monotonic()
        if stats['accepted'] >= accepted and stats['active'] == 0:
            return now - go
        if now - go > GOALS_TIMEOUT_S:
            raise TimeoutError(f'goals not done within {GOALS_TIMEOUT_S:.0f} s: {stats}')
        if now - shown >= 10:
            shown = now
            say(f'    {now - go:.0f} s: {stats["accepted"]}/{accepted} accepted, '
                f'{stats["active"]} active')
        time.sleep(0.5)


def run_round(args: argparse.Namespace, server_kind: str, domain: int) -> dict[str, Any]:
    """One server, the observers and the plain clients; every process stopped however it ends."""
    env = plain_env(domain)
    action = f'/status_observer_{os.urandom(4).hex()}'
    prefix = guard_command() if server_kind == 'guarded' else []
    server = Proc('server', prefix + python_module('harness.server', action, args.period,
                                                   '--depth', DEPTH), env)
    procs: list[Proc] = []
    try:
        server.expect('READY', 60)
        observers = {config: Proc(f'{config} observer', python_module(
            'harness.client', action, config, 1, args.order, DEPTH), env)
            for config in args.configs}
        plain = [Proc(f'plain client {i}', python_module(
            'harness.client', action, 'rclpy', args.goals, args.order, DEPTH), env)
            for i in range(args.plain_clients)]
        procs = [*observers.values(), *plain]
        for proc in procs:
            proc.expect('READY', 120)
        base = server.request_json('stats', 'STATS')['accepted']
        go = time.monotonic()
        for proc in procs:
            proc.send('go')
        goals_s = wait_for_goals(server, base + args.plain_clients * args.goals + len(observers),
                                 go)
        load.wait_for_quiet(procs, go, 0.0, GOALS_TIMEOUT_S, say)
        reports = {config: proc.request_json('report', 'RESULT', 60)
                   for config, proc in observers.items()}
        plain_cpu = [p.request_json('report', 'RESULT', 60)['cpu_s'] for p in plain]
        stats = server.request_json('stats', 'STATS', 60)
    finally:
        for proc in procs:
            proc.stop()
        server.stop()
    return {'server': server_kind, 'goals_s': goals_s, 'server_cpu_s': stats['cpu_s'],
            'plain_clients_cpu_s': plain_cpu,
            'observers': {config: {k: v for k, v in report.items() if k != 'latency_us'}
                          for config, report in reports.items()}}


def fast_dds_cpu_s(report: dict[str, Any]) -> Optional[float]:
    """The CPU seconds of a client's Fast DDS threads (``dds.*``: receive, events, flow control),
    the rest being Python's; None in results from before they were recorded."""
    threads = report.get('thread_cpu_s')
    return None if threads is None else sum(
        s for name, s in threads.items() if name.startswith('dds.'))


def table(result: dict[str, Any]) -> str:
    """Per server kind and configuration: the observer's CPU over the rounds, and its ratio."""
    rows = []
    configs = result['args']['configs']
    for kind in result['args']['servers']:
        rounds = [r for r in result['rounds'] if r['server'] == kind]
        plain = [r['observers']['rclpy']['cpu_s'] for r in rounds] if 'rclpy' in configs else []
        for config in configs:
            cpu = [r['observers'][config]['cpu_s'] for r in rounds]
            ratios = [c / p for c, p in zip(cpu, plain) if p] if plain else []
            first = rounds[0]['observers'][config] if rounds else {}
            dds = [fast_dds_cpu_s(r['observers'][config]) for r in rounds]
            rows.append([
                kind, load.CONFIG_LABELS[config], ' / '.join(f'{c:.2f}' for c in cpu),
                ' / '.join(fmt(d, '.2f') for d in dds),
                fmt(statistics.median(ratios) if ratios else None, '.2f') + 'x',
                ' / '.join(f'{r:.2f}' for r in ratios),
                fmt(first.get('status'), 'd'), fmt(first.get('status_entries'), 'd'),
                fmt(first.get('status_entries_listed'), 'd'),
                fmt(first.get('responses_dropped'), 'd'),
                ' / '.join(f"{r['goals_s']:.0f}" for r in rounds)])
    return '\n'.join(markdown_table(
        ['server', 'observer', 'CPU s per round', 'of it, Fast DDS threads',
         'median ratio to plain', 'ratios',
         'status samples to Python (round 1)', 'entries to Python (round 1)',
         'entries listed (round 1)', "others' responses dropped before Python (round 1)",
         'goals took s'], rows,
        ['---', '---'] + ['---:'] * 9))


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run every round, write the results after each, and print the table."""
    args = parse_args(argv)
    if args.markdown:
        say(table(json.loads(args.markdown.read_text())))
        return 0
    now = datetime.datetime.now(datetime.timezone.utc)
    out = args.out or (ROOT / 'benchmarks' / 'results' /
                       f'status-observer-{now:%Y-%m-%d}-{platform.node()}.json')
    out.parent.mkdir(parents=True, exist_ok=True)
    say(machine_line())
    result: dict[str, Any] = {
        'benchmark': 'status_observer', 'date': now.isoformat(timespec='seconds'),
        'host': platform.node(), 'machine': environment_facts(),
        'command': ' '.join(['python', '-m', 'benchmarks.status_observer',
                             *(argv if argv is not None else sys.argv[1:])]),
        'args': {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()},
        'load_average_start': os.getloadavg(), 'rounds': []}
    domain = unused_domain()
    for n in range(1, args.rounds + 1):
        for kind in args.servers:
            say(f'round {n}/{args.rounds}, {kind} server: {args.plain_clients} plain clients x '
                f'{args.goals} goals, observers {", ".join(args.configs)}; load average '
                f'{os.getloadavg()[0]:.2f}')
            one = run_round(args, kind, domain)
            result['rounds'].append(one)
            say('  observer CPU s: ' + ', '.join(
                f'{config} {report["cpu_s"]:.2f}' for config, report in one['observers'].items())
                + f'; goals took {one["goals_s"]:.1f} s')
            result['load_average_end'] = os.getloadavg()
            out.write_text(json.dumps(result, indent=1))
    say('\n' + table(result) + f'\n\nresults: {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
