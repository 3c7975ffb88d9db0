"""Action feedback on the wire on Fast DDS 3.3+: what each client receives, with the guard's
feedback prefilter (cft_action/native/guard/_guard_feedback.c) and without it.

There the library's client marks its feedback reader (USER_DATA) and a guarded server's feedback
writer sends it only its own goals' feedback; plain clients get all of it. This runs, alternating,
a guarded server, one with ``CFT_GUARD_FEEDBACK=off`` and, with ``--unguarded``, one without the
guard, each with three of the library's clients and a plain rclpy one (``--goals`` goals of
``--order`` feedback messages each, the k-th carrying k + 1 int32), on UDP only, through
:func:`tests.support.clients_on_the_wire`: a raw socket on loopback counts the feedback writer's
DATA and bytes (DATA, GAPs, HEARTBEATs) by destination port, one port per client's participant
(all runs' ports together: a port that got only its client's goals, or all).

Needs root, and the stack's environment (``compat/stack_env.sh``).

    python -m benchmarks.feedback_wire --rounds 3 --order 100 --unguarded
"""

from __future__ import annotations

import argparse
import statistics
import sys
from typing import Any

from harness.capture import samples_by_port
from harness.report import alternating_main, markdown_table
from tests.support import clients_on_the_wire

#: Three of the library's clients (default mode) and one plain.
MODES = ('client', 'client', 'client', 'rclpy')
CONFIGS = {'prefilter on': (True, {}),
           'CFT_GUARD_FEEDBACK=off': (True, {'CFT_GUARD_FEEDBACK': 'off'}),
           'unguarded': (False, {})}


def measure(config: str, goals: int, order: int) -> dict[str, Any]:
    """One run: per port (one per client), the feedback samples and bytes it received, and whether
    they were its client's own goals' only."""
    guarded, env = CONFIGS[config]
    run = clients_on_the_wire([(mode, goals, order) for mode in MODES], samples_by_port,
                              guarded=guarded, server_env=env, together=True)
    every = len(MODES) * goals * order
    ports = [{'own_only': len(seen.samples) < every, 'samples': len(seen.samples),
              'bytes': seen.octets - seen.resent_octets} for seen in run.captured.values()]
    return {'config': config, 'ports': ports,
            'filtered_in': [report.get('filtered_in') for report in run.reports],
            'complete_goals': [report['complete_goals'] for report in run.reports],
            'guard_feedback': run.stats_after.get('guard_feedback')}


def markdown(result: dict[str, Any]) -> str:
    """Per server: the feedback samples and bytes of the ports that received their client's goals'
    only (the library's clients under the prefilter), and of those that received all."""
    rows = []
    for config in result['configs']:
        row = [config]
        for own_only in (True, False):
            ports = [p for r in result['runs'] if r['config'] == config for p in r['ports']
                     if p['own_only'] == own_only]
            row += [f'{len(ports)}',
                    f"{statistics.median(p['samples'] for p in ports):,.0f}" if ports else '-',
                    f"{statistics.median(p['bytes'] for p in ports):,.0f}" if ports else '-']
        rows.append(row)
    return '\n'.join(markdown_table(
        ['server', 'ports, own goals only', 'samples (median)', 'bytes (median)',
         'ports, all goals', 'samples (median)', 'bytes (median)'], rows,
        ['---'] + ['---:'] * 6))


def main(argv: list[str]) -> None:
    def arguments(parser: argparse.ArgumentParser) -> None:
        parser.add_argument('--goals', type=int, default=3, help='goals per client')
        parser.add_argument('--order', type=int, default=100, help='feedback messages per goal')

    def run(args: argparse.Namespace, configs: list[str]) -> dict[str, Any]:
        return {'modes': MODES, 'goals': args.goals, 'order': args.order,
                'runs': [measure(config, args.goals, args.order) for _ in range(args.rounds)
                         for config in configs]}

    alternating_main('feedback_wire', argv, __doc__, arguments, list(CONFIGS), run, markdown)


if __name__ == '__main__':
    main(sys.argv[1:])
