"""The multi-client load demo (``make demo``): what content-filtered feedback saves, measured.

One Fibonacci action server process, under the server guard, and N client processes that each send M
goals with feedback at once; three configurations run one after another under the same load: plain
``rclpy.action.ActionClient``, ``cft_action.ActionClient`` in ``client`` mode, and in ``goals``
mode. Then a second server, **without** the guard (the server of someone who only changed a client's
import), serves plain rclpy and ``client`` mode under the same load, alternating, twice each
(plain, cft, cft, plain): it filters nothing, and the clients' own DDS readers drop other goals'
feedback. Its rows pool each configuration's two phases and refer to its own plain phases, so that
its server's CPU per message compares the clients, not two processes. For each it prints, per
client process, the feedback messages taken from rcl (own and foreign), the bytes received, the
client CPU seconds, the filter updates and the latency from the server's publish to the user
callback, with ratios to plain; then it writes a PNG plot and a JSON file with every raw figure,
and prints their paths.

Bytes are real network bytes when network namespaces can be made (root and iproute2): every client
then has a namespace and an interface of its own. Otherwise they are estimated from the message
counts, and the output says so.

The server's feedback writer keeps rclpy's default of 10 samples, as a user's server does
(``--server-feedback-depth N``; ``all`` keeps every sample of a phase, which flatters the bytes:
with a full keep-last history Fast DDS heartbeats every reader at every write, which the guard
narrows; docs/INTERNALS.md, section 22).

Usage: ``python -m demos.load_demo [--clients 8] [--goals 4] [--order 1000] [--rate 100]
[--server-feedback-depth 10] ...``
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path
from typing import Optional, Sequence

from harness import load
from harness.cli import add_server_feedback_depth
from harness.machine import environment_facts
from harness.proc import add_cpu_arguments

#: rclpy's default feedback depth (``ActionServer``'s ``feedback_pub_qos_profile``, keep-last 10).
RCLPY_FEEDBACK_DEPTH = 10

DEFAULT_OUTPUT = Path(__file__).resolve().parent.parent / 'demo-output'


def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    """The command line; the defaults are the demo of the issue."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument('--clients', type=int, default=8, help='client processes (N)')
    parser.add_argument('--goals', type=int, default=4, help='goals per client, sent at once (M)')
    parser.add_argument('--order', type=int, default=1000, help='feedback messages per goal')
    parser.add_argument('--rate', type=float, default=100.0, help='feedback rate per goal, Hz')
    parser.add_argument('--pad', type=int, default=0,
                        help='int32 elements added to each feedback message (2500: 10 kB)')
    parser.add_argument('--configs', default='rclpy,client,goals',
                        help='comma-separated, from: ' + ', '.join(load.CONFIG_LABELS))
    parser.add_argument('--unguarded', default='rclpy,client',
                        help='comma-separated configurations run after them against a second '
                             'server without the guard (empty: none); its ratios refer to its '
                             'own plain rclpy phases, when it runs them')
    parser.add_argument('--unguarded-rounds', type=int, default=2,
                        help='phases of each configuration on the unguarded server, the order '
                             'reversed in even rounds, pooled in its rows')
    parser.add_argument('--network', choices=('auto', 'netns', 'count'), default='auto',
                        help='bytes from per-client network namespaces (auto: when possible) or '
                             'estimated from message counts')
    parser.add_argument('--output', type=Path, default=DEFAULT_OUTPUT,
                        help='directory for load_demo.png and load_demo.json')
    parser.add_argument('--no-plot', action='store_true', help='skip the PNG')
    add_server_feedback_depth(parser, default=RCLPY_FEEDBACK_DEPTH)
    add_cpu_arguments(parser)
    args = parser.parse_args(argv)
    args.configs = [c.strip() for c in args.configs.split(',') if c.strip()]
    args.unguarded = [c.strip() for c in args.unguarded.split(',') if c.strip()]
    unknown = set(args.configs + args.unguarded) - set(load.CONFIG_LABELS)
    if unknown:
        parser.error(f'unknown configurations: {", ".join(sorted(unknown))}')
    return args


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the demo; return the exit status."""
    args = parse_args(argv)
    started = time.monotonic()

    def progress(line: str) -> None:
        print(f'[{time.monotonic() - started:6.1f} s] {line}', flush=True)

    spec = load.LoadSpec(clients=args.clients, goals=args.goals, order=args.order,
                         rate_hz=args.rate, pad=args.pad, network=args.network,
                         server_feedback_depth=args.server_feedback_depth,
                         server_cpus=args.server_cpus, client_cpus=args.client_cpus)
    progress(f'load: {spec.clients} client processes x {spec.goals} goals, {spec.order} '
             f'feedback messages per goal at {spec.rate_hz:g} Hz; configurations: '
             + ', '.join(load.CONFIG_LABELS[c] for c in args.configs))
    machine = environment_facts()  # before the run: its load average is the one at the start
    result = load.run_load(spec, args.configs, progress)
    if args.unguarded:
        progress('a second server, without the guard: '
                 + ', '.join(load.CONFIG_LABELS[c] for c in args.unguarded))
        unguarded = load.run_load(dataclasses.replace(spec, guarded=False), args.unguarded,
                                  progress, rounds=args.unguarded_rounds)
        result['phases'] += unguarded['phases']
        result['unguarded_round_phases'] = unguarded.get('round_phases', [])
    result['machine'] = machine
    result['load_average_at_end'] = os.getloadavg()
    result['elapsed_s'] = time.monotonic() - started
    print()
    print(load.format_table(result))
    print()
    args.output.mkdir(parents=True, exist_ok=True)
    json_path = args.output / 'load_demo.json'
    json_path.write_text(json.dumps(result, indent=1))
    print(f'raw figures: {json_path}')
    if not args.no_plot:
        from harness.plot import demo_figure
        png = demo_figure(result, args.output / 'load_demo.png')
        print(f'plot: {png}')
    print(f'done in {time.monotonic() - started:.0f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
