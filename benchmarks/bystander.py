"""Bystander cost: the bytes a plain client receives per feedback sample next to filtered clients.

Fast DDS 2.14 adds a ``PID_CONTENT_FILTER_INFO`` inline QoS (16 bytes of filter signature per
filtered reader, and a small header) to every DATA that a writer with filtered readers sends, to
its unfiltered readers too. A plain rclpy client that takes every goal's feedback (a *bystander*,
like a dashboard) therefore pays for the filtered clients next to it, in every sample.

This benchmark measures it on the wire. One guarded server per feedback size serves, one phase
after another, one plain rclpy bystander (:attr:`harness.load.LoadSpec.bystanders`) next to K
neighbours, each process in its own network namespace (:mod:`harness.netns`):

- K = 0: the bystander alone (and once more at the end, to show that the writer is back to
  unfiltered DATA once the filtered readers are gone);
- for each K > 0: K plain rclpy neighbours, then K ``cft_action`` clients in ``client`` mode, so
  that at each K the only difference is the filter.

Every process, the bystander included, sends M goals at once. The bystander's figure is the
``rx_bytes`` of its own interface over the phase's window divided by the feedback samples it took
(own and foreign: every goal's). A packet capture on the bystander's interface
(``harness.capture``, off with ``--no-capture``) splits those bytes into feedback data,
GAPs/heartbeats, status, discovery and other, so that the feedback data per sample, which is where
the filter signatures go, is visible apart from status (whose share grows with the number of
goals, equally in both columns).

Results (machine, date, command, versions, load averages, every raw figure) go to
``benchmarks/results/bystander-<date>-<host>.json`` after every phase; the plot to
``docs/img/bystander.png``; the tables are printed in Markdown::

    python -m benchmarks.bystander --neighbours 0,8,16,32 --sizes small,1k

Needs root (network namespaces). ``--markdown FILE`` prints the tables and redraws the plot of a
results file.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any, Optional, Sequence

from harness import load
from harness.capture import CATEGORIES
from harness.cli import add_server_feedback_depth, int_list, name_list
from harness.machine import environment_facts
from harness.report import fmt

REPO = Path(__file__).resolve().parent.parent
#: The neighbours' configurations, in the order they run at each K.
NEIGHBOUR_CONFIGS = ('rclpy', 'client')


def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument('--neighbours', type=int_list, default=[0, 8, 16, 32],
                        help='numbers K of neighbour client processes, comma-separated (0: the '
                             'bystander alone)')
    parser.add_argument('--sizes', type=name_list(load.SIZES), default='small,1k',
                        help='feedback sizes, comma-separated, from: ' + ', '.join(load.SIZES))
    parser.add_argument('--goals', type=int, default=1,
                        help='goals per client process, the bystander included (M)')
    parser.add_argument('--rate', type=float, default=5.0,
                        help='feedback rate per goal, Hz (K + 1 plain clients each take all '
                             '(K + 1) x M x rate messages a second: keep it within the machine)')
    parser.add_argument('--duration', type=float, default=10.0,
                        help='seconds of feedback per goal (order = duration x rate)')
    parser.add_argument('--settle', type=float, default=4.0,
                        help='seconds of quiet after the last goal before a phase is accounted '
                             '(more than the server\'s 2 s result timeout, whose status is '
                             'counted)')
    add_server_feedback_depth(parser)
    parser.add_argument('--no-capture', action='store_true',
                        help='no packet capture on the bystander: rx_bytes only')
    parser.add_argument('--output', type=Path, default=None,
                        help='results file (default: benchmarks/results/bystander-<date>-<host>'
                             '.json)')
    parser.add_argument('--plot', type=Path, default=REPO / 'docs' / 'img' / 'bystander.png',
                        help='the PNG plot')
    parser.add_argument('--markdown', type=Path, default=None, metavar='RESULTS',
                        help='run nothing: print the tables and redraw the plot of a results file')
    args = parser.parse_args(argv)
    args.neighbours = sorted(set(args.neighbours))
    return args


def plan(neighbours: Sequence[int]) -> list[tuple[str, int]]:
    """The phases of one size, as (neighbours' configuration, K): the bystander alone, plain
    and filtered neighbours at each K > 0, and the bystander alone again."""
    phases = [('rclpy', 0)]
    for k in neighbours:
        if k > 0:
            phases += [(config, k) for config in NEIGHBOUR_CONFIGS]
    return phases + [('rclpy', 0)]


def add_ratios(rows: list[dict[str, Any]]) -> None:
    """Add to each row its ratios to the first K = 0 row and to the plain neighbours' row of the
    same K, for the whole bytes and for the feedback data alone."""
    alone = next(r for r in rows if r['neighbours'] == 0)
    plain = {r['neighbours']: r for r in rows if r['neighbour_config'] == 'rclpy'}
    keys = {'rx': lambda r: r['rx_bytes_per_sample'],
            'feedback_data': lambda r: r.get('per_sample', {}).get('feedback data')}
    for row in rows:
        twin = plain.get(row['neighbours'])
        for name, value in keys.items():
            mine, base = value(row), value(alone)
            row[f'{name}_to_alone'] = mine / base if mine is not None and base else None
            other = value(twin) if twin else None
            row[f'{name}_to_plain_neighbours'] = (mine / other if mine is not None and other
                                                  else None)
        if twin is not None and row is not twin and row['neighbours']:
            mine, other = keys['feedback_data'](row), keys['feedback_data'](twin)
            row['feedback_data_bytes_per_filtered_reader'] = (
                (mine - other) / row['neighbours'] if mine is not None and other is not None
                else None)


def run_size(size: str, args: argparse.Namespace, record: dict[str, Any],
             save: Any, progress: load.Progress) -> None:
    """Run the phases of one feedback size against one server, into ``record``; ``save()`` after
    every phase."""
    spec = load.LoadSpec(clients=max(args.neighbours), goals=args.goals,
                         order=max(1, round(args.duration * args.rate)), rate_hz=args.rate,
                         pad=load.SIZES[size], network='netns', settle_s=args.settle,
                         bystanders=1, server_feedback_depth=args.server_feedback_depth)
    record.update({'size': size, 'spec': dataclasses.asdict(spec), 'phases': [], 'rows': []})
    run_class = load.LoadRun if args.no_capture else load.CapturingRun
    run = run_class(spec, progress)
    record['queue_depth'] = run.depth
    record['network_note'] = run.network_note
    try:
        phases = plan(args.neighbours)
        for i, (config, k) in enumerate(phases, 1):
            progress(f'{size}: phase {i}/{len(phases)}: bystander next to {k} '
                     f'{load.CONFIG_LABELS[config] if k else "neighbours"}')
            phase = run.run_phase(config, clients=k)
            phase['load_average_at_end'] = os.getloadavg()
            record['phases'].append(phase)
            record['rows'].append(load.bystander_figures(phase))
            row = record['rows'][-1]
            progress(f'    bystander: {row["samples"]} samples of {row["published"]} published, '
                     f'{fmt(row["rx_bytes_per_sample"], ".1f")} B per sample on the wire')
            add_ratios(record['rows'])
            save()
    finally:
        run.close()


# --- presentation ---------------------------------------------------------------------------------

def _row_at(rows: list[dict[str, Any]], k: int, config: str) -> Optional[dict[str, Any]]:
    return next((r for r in rows if r['neighbours'] == k
                 and (k == 0 or r['neighbour_config'] == config)), None)


def markdown(results: dict[str, Any]) -> str:
    """One table per size: the bystander's bytes per sample next to plain and next to filtered
    neighbours, side by side, then its bytes per sample by kind in every phase."""
    out = []
    for record in results['sizes']:
        rows = record.get('rows')
        if record.get('error'):
            out.append(f"**{record.get('size')}**: failed: {record['error'].splitlines()[0]}\n")
        if not rows:
            continue
        spec = record['spec']
        size = rows[0]['feedback_message_bytes']
        out.append(f"**{record['size']} feedback ({size} B), M = {spec['goals']} goal(s) per "
                   f"process, {spec['order']} feedback per goal at {spec['rate_hz']:g} Hz**\n")
        out.append('| K neighbours | next to K plain: B/sample | × K=0 | next to K `client`: '
                   'B/sample | × K=0 | × plain | feedback data B/sample, plain / `client` | '
                   '× plain | B per filtered reader | samples (lost) |')
        out.append('|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|')
        for k in sorted({r['neighbours'] for r in rows}):
            plain, cft = _row_at(rows, k, 'rclpy'), _row_at(rows, k, 'client')
            if k == 0:  # the bystander alone, first (and again at the end, in the notes)
                cft = plain
            if plain is None or cft is None:
                continue
            data = [r.get('per_sample', {}).get('feedback data') for r in (plain, cft)]
            out.append(
                f"| {k} | {fmt(plain['rx_bytes_per_sample'], '.1f')} | "
                f"{fmt(plain['rx_to_alone'], '.3f')} | {fmt(cft['rx_bytes_per_sample'], '.1f')} "
                f"| {fmt(cft['rx_to_alone'], '.3f')} | "
                f"{fmt(cft['rx_to_plain_neighbours'], '.3f')} | "
                f"{fmt(data[0], '.1f')} / {fmt(data[1], '.1f')} | "
                f"{fmt(cft['feedback_data_to_plain_neighbours'], '.3f')} | "
                f"{fmt(cft.get('feedback_data_bytes_per_filtered_reader'), '.1f')} | "
                f"{plain['samples']} ({plain['lost']}) / {cft['samples']} ({cft['lost']}) |")
        filtered = [r for r in rows if r['neighbour_config'] == 'client' and 'per_sample' in r]
        if len(filtered) >= 2:
            first, last = filtered[0], filtered[-1]
            slope = ((last['per_sample']['feedback data'] - first['per_sample']['feedback data'])
                     / (last['neighbours'] - first['neighbours']))
            out.append(f"\nFeedback data per sample grows by {slope:.1f} B per filtered neighbour "
                       f"from K = {first['neighbours']} to K = {last['neighbours']}.")
        again = [r for r in rows if r['neighbours'] == 0][1:]
        if again:
            out.append(f"\nThe bystander alone again after the filtered neighbours left: "
                       f"{fmt(again[-1]['rx_bytes_per_sample'], '.1f')} B/sample "
                       f"(× K=0: {fmt(again[-1]['rx_to_alone'], '.3f')}), feedback data "
                       f"{fmt(again[-1].get('per_sample', {}).get('feedback data'), '.1f')}.")
        if any('per_sample' in r for r in rows):
            out.append('\n*The bystander\'s received bytes per feedback sample, by kind '
                       '(captured)*\n')
            out.append('| neighbours | ' + ' | '.join(CATEGORIES) + ' | total | packets/sample |')
            out.append('|---|' + '---:|' * (len(CATEGORIES) + 2))
            for r in rows:
                if 'per_sample' not in r:
                    continue
                who = (f"{r['neighbours']} {load.CONFIG_LABELS[r['neighbour_config']]}"
                       if r['neighbours'] else 'none (alone)')
                per = r['per_sample']
                out.append(f"| {who} | " + ' | '.join(f'{per[c]:.1f}' for c in CATEGORIES)
                           + f" | {sum(per.values()):.1f} | "
                           f"{fmt(r['packets_per_sample'], '.2f')} |")
        loads = [r['load_average_at_end'] for r in rows if r.get('load_average_at_end')]
        if loads:
            out.append(f"\nLoad average (1 min) at the end of the phases: "
                       f"{min(a[0] for a in loads):.1f}–{max(a[0] for a in loads):.1f}.")
        out.append('')
    return '\n'.join(out)


def plot(results: dict[str, Any], path: Path) -> Path:
    """Bytes per sample against K, next to plain and next to filtered neighbours, one panel per
    size (solid: everything received; dashed: feedback data alone); return the path."""
    from harness.plot import COLOURS, pyplot, save
    plt = pyplot()
    records = [r for r in results['sizes'] if r.get('rows')]
    if not records:
        return path
    fig, axes = plt.subplots(1, len(records), figsize=(6.2 * len(records), 4.6), squeeze=False)
    for ax, record in zip(axes[0], records):
        rows = record['rows']
        alone = rows[0]
        for config in NEIGHBOUR_CONFIGS:
            series = [alone] + [r for r in rows if r['neighbours'] and
                                r['neighbour_config'] == config]
            ks = [r['neighbours'] for r in series]
            label = 'next to K ' + ('plain rclpy' if config == 'rclpy' else 'cft `client`')
            ax.plot(ks, [r['rx_bytes_per_sample'] for r in series], 'o-', color=COLOURS[config],
                    label=label + ': all bytes')
            if all('per_sample' in r for r in series):
                ax.plot(ks, [r['per_sample']['feedback data'] for r in series], 's--',
                        color=COLOURS[config], label=label + ': feedback data')
        ax.set_ylim(bottom=0)
        ax.set_xlabel('neighbour client processes K')
        ax.set_ylabel('bytes received per feedback sample (on the wire)')
        ax.set_title(f"plain bystander, {alone['feedback_message_bytes']} B feedback, "
                     f"{record['spec']['rate_hz']:g} Hz", fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle('What a plain rclpy client pays per sample for filtered clients next to it',
                 fontsize=11)
    return save(fig, path)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the benchmark (or only present a results file); print the tables and the paths."""
    args = parse_args(argv)
    if args.markdown:
        results = json.loads(args.markdown.read_text())
    else:
        started = time.monotonic()
        date = datetime.date.today().isoformat()
        output = args.output or (REPO / 'benchmarks' / 'results' /
                                 f'bystander-{date}-{platform.node()}.json')
        output.parent.mkdir(parents=True, exist_ok=True)
        results = {
            'benchmark': 'bystander',
            'command': ' '.join([Path(sys.executable).name, '-m', 'benchmarks.bystander',
                                 *(sys.argv[1:] if argv is None else argv)]),
            'date': datetime.datetime.now().astimezone().isoformat(timespec='seconds'),
            'machine': environment_facts(),
            'args': {'neighbours': args.neighbours, 'sizes': args.sizes, 'goals': args.goals,
                     'rate_hz': args.rate, 'duration_s': args.duration, 'settle_s': args.settle,
                     'capture': not args.no_capture},
            'sizes': [],
        }

        def progress(line: str) -> None:
            print(f'[{time.monotonic() - started:7.1f} s] {line}', flush=True)

        def save() -> None:
            results['elapsed_s'] = time.monotonic() - started
            output.write_text(json.dumps(results, indent=1))

        for size in args.sizes:
            record: dict[str, Any] = {}
            results['sizes'].append(record)
            try:
                run_size(size, args, record, save, progress)
            except Exception as e:  # noqa: BLE001 (the failure is a result too; next size)
                progress(f'{size} failed: {e}')
                record['error'] = str(e)[:2000]
            save()
        results['load_average_at_end'] = os.getloadavg()
        save()
        progress(f'results: {output}')
    print(markdown(results))
    print(f'plot: {plot(results, args.plot)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
