"""Action replies on the wire: what each client receives, and what the server spends per goal, with
the guard's reply filter (cft_action/native/guard/_guard_replies.c) and without it.

rmw_fastrtps writes every goal, cancel and result reply to every client's response reader. Under the
guard, a reply goes only to the readers of the participant whose request it answers. This runs, side
by side and alternating, a guarded server with the filter on and one with ``CFT_GUARD_REPLIES=off``
(and, with ``--unguarded``, a server without the guard), each with the issue's clients (three of
the library's in ``client`` mode and a plain rclpy one, 3 goals of 2 feedback messages each), on UDP
only, through :func:`tests.test_replies.replies_on_the_wire`: a raw socket on loopback counts the
reply writers' DATA and bytes by destination port (one port per client's participant), and the
server's ``cpu_s`` from ``go`` to the end, divided by the goals, is its CPU per goal. Needs root.

    python -m benchmarks.replies --rounds 3 --result-pads 0,25000
"""

from __future__ import annotations

import argparse
import statistics
import sys
from typing import Any

from harness.cli import int_list
from harness.report import alternating_main, markdown_table
from tests.test_replies import ports, replies_on_the_wire

#: The issue's clients: three of the library's (default mode) and one plain, 3 goals each.
CLIENTS = (('client', 3), ('client', 3), ('client', 3), ('rclpy', 3))
CONFIGS = {'filter on': (True, {}), 'CFT_GUARD_REPLIES=off': (True, {'CFT_GUARD_REPLIES': 'off'}),
           'unguarded': (False, {})}


def measure(config: str, result_pad: int) -> dict[str, Any]:
    """One run: per client port, the replies and bytes received; the server's CPU per goal."""
    guarded, env = CONFIGS[config]
    run = replies_on_the_wire(guarded, CLIENTS, result_pad, env)
    goals = sum(goals for _, goals in CLIENTS)
    cpu_s = run.stats_after['cpu_s'] - run.stats_at_go['cpu_s']
    return {'config': config, 'result_pad': result_pad,
            'replies': sorted(len(seen.samples) for seen in ports(run).values()),
            'bytes': sorted(seen.octets - seen.resent_octets for seen in ports(run).values()),
            'resent_bytes': sum(seen.resent_octets for seen in ports(run).values()),
            'server_cpu_ms_per_goal': 1000 * cpu_s / goals,
            'guard_replies': run.stats_after['guard_replies'],
            'results': [report['results'] for report in run.reports]}


def markdown(result: dict[str, Any]) -> str:
    """The table of a results file: per result size and server, the replies and bytes each
    client received, and the server's CPU per goal."""
    rows = []
    for pad in result['result_pads']:
        for config in result['configs']:
            mine = [r for r in result['runs'] if r['config'] == config and r['result_pad'] == pad]
            rows.append([f'{4 * pad + 4} B', config,
                         ' / '.join(str(r['replies']) for r in mine),
                         f"{statistics.median(b for r in mine for b in r['bytes']):,.0f}",
                         f"{statistics.median(r['server_cpu_ms_per_goal'] for r in mine):.2f}"])
    return '\n'.join(markdown_table(['result', 'server', 'replies per client (each run)',
                                     'reply bytes per client (median)',
                                     'server CPU ms per goal (median)'], rows))


def main(argv: list[str]) -> None:
    def arguments(parser: argparse.ArgumentParser) -> None:
        parser.add_argument('--result-pads', type=int_list, default=[0, 25000],
                            help='int32 elements appended to each result')

    def run(args: argparse.Namespace, configs: list[str]) -> dict[str, Any]:
        return {'clients': CLIENTS, 'result_pads': args.result_pads,
                'runs': [measure(config, pad) for _ in range(args.rounds)
                         for pad in args.result_pads for config in configs]}

    alternating_main('replies', argv, __doc__, arguments, list(CONFIGS), run, markdown)


if __name__ == '__main__':
    main(sys.argv[1:])
