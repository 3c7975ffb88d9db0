"""The benchmark sweep (``make bench``): four configurations over a grid of loads.

For every load point (N client processes x M goals each, feedback rate, feedback size) one server
(guarded, or not with ``--guard off``) runs four configurations one after another, through the
same harness as ``make demo`` (:mod:`harness.load`):

- ``rclpy``: plain ``rclpy.action.ActionClient``;
- ``client`` and ``goals``: ``cft_action.ActionClient`` in those modes;
- ``upstream``: the upstream (Rolling) design, emulated in :mod:`harness.upstream`.

Each goal lasts ``--duration`` seconds (``order = duration x rate`` feedback messages). Results,
with the machine, the versions, the command and every raw figure, go to
``benchmarks/results/<date>-<host>.json`` after every point, so an interrupted sweep keeps what it
measured; plots go to ``docs/img/``. ``--plot-only FILE`` redraws the plots of a results file.

The default grid is the issue's: N in {1, 2, 4, 8, 16, 32, 40}, M in {1, 4, 16}, 10 and 100 Hz,
small and 10 kB feedback: 84 points, several hours on a small machine, and past a few thousand
feedback messages per second the Python server cannot keep the rate (the results record the rate it
achieved). A reduced grid, as in docs/BENCHMARKS.md::

    python -m benchmarks.sweep --clients 1,4,16,32,40 --goals 1,4 --rates 100 --sizes small

``--anatomy`` instead runs one point with a packet capture on one client per configuration, to
break its received bytes down by kind (feedback data, GAPs, status, discovery), and draws that
breakdown (``docs/img/anatomy_n<N>m<M>_<size>.png``). Sizes: ``small`` (36 B), ``1k``, ``4k``
and ``10k`` feedback messages (:data:`harness.load.SIZES`)::

    python -m benchmarks.sweep --anatomy --clients 16 --goals 4 --rates 100 --sizes 4k
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any, Optional, Sequence

from harness import load
from harness.cli import add_server_feedback_depth, float_list, int_list, name_list
from harness.machine import environment_facts
from harness.report import fmt

REPO = Path(__file__).resolve().parent.parent

SIZES = load.SIZES  # int32 elements of padding: 'small' (36 B), '1k', '4k', '10k'
#: Fast DDS's writer keeps filters for at most this many readers (reader_filters_allocation), unless
#: the server guard raises the limit (CFT_ACTION_READER_FILTERS, default 1024).
WRITER_FILTER_LIMIT = 32


def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    """The command line; the defaults are the grid of the issue."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument('--clients', type=int_list, default=[1, 2, 4, 8, 16, 32, 40],
                        help='client process counts N, comma-separated')
    parser.add_argument('--goals', type=int_list, default=[1, 4, 16],
                        help='goals per client M, comma-separated')
    parser.add_argument('--rates', type=float_list, default=[10.0, 100.0],
                        help='feedback rates per goal in Hz, comma-separated')
    parser.add_argument('--sizes', type=name_list(SIZES), default='small,10k',
                        help='feedback sizes, comma-separated, from: ' + ', '.join(SIZES))
    parser.add_argument('--duration', type=float, default=2.0,
                        help='seconds of feedback per goal (order = duration x rate)')
    parser.add_argument('--configs', type=name_list(load.CONFIG_LABELS),
                        default='rclpy,client,goals,upstream',
                        help='comma-separated, from: ' + ', '.join(load.CONFIG_LABELS))
    parser.add_argument('--network', choices=('auto', 'netns', 'count'), default='auto')
    parser.add_argument('--guard', choices=('on', 'off'), default='on',
                        help="'off': the server runs without `cft-action guard`, as the server of "
                             'someone who only swapped a client import')
    add_server_feedback_depth(parser)
    parser.add_argument('--loss', type=float, default=0.0,
                        help='percent of the server\'s packets that each client drops as they '
                             'arrive (iptables in its network namespace)')
    parser.add_argument('--drain-timeout', type=float, default=300.0,
                        help='seconds a phase may take after its goals finished')
    parser.add_argument('--goals-timeout', type=float, default=None,
                        help='seconds the goals of a phase may take (default: 120 + 30 x duration)')
    parser.add_argument('--output', type=Path, default=None,
                        help='results file (default: benchmarks/results/<date>-<host>.json)')
    parser.add_argument('--plots', type=Path, default=REPO / 'docs' / 'img',
                        help='directory for the PNG plots')
    parser.add_argument('--plot-only', type=Path, default=None, metavar='RESULTS',
                        help='only redraw the plots of a results file')
    parser.add_argument('--anatomy', action='store_true',
                        help='one point (the first of each list) with a packet capture on one '
                             'client per configuration')
    return parser.parse_args(argv)


def grid(args: argparse.Namespace) -> list[dict[str, Any]]:
    """The load points, cheapest first, so that a partial sweep covers the small loads."""
    points = [{'clients': n, 'goals': m, 'rate_hz': rate, 'size': size}
              for n, m, rate, size in itertools.product(args.clients, args.goals, args.rates,
                                                        args.sizes)]
    if args.anatomy:
        points = points[:1]
    return sorted(points, key=lambda p: p['clients'] * p['goals'] * p['rate_hz']
                  * (1 + SIZES[p['size']]))


def default_output() -> Path:
    """``benchmarks/results/<date>-<host>.json``."""
    date = datetime.date.today().isoformat()
    return REPO / 'benchmarks' / 'results' / f'{date}-{platform.node()}.json'


def run(args: argparse.Namespace) -> Path:
    """Run the sweep, writing the results file after every point; return its path."""
    output = args.output or default_output()
    if args.anatomy:
        output = output.with_name(output.stem + '-anatomy.json')
    output.parent.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    results: dict[str, Any] = {
        'command': ' '.join([Path(sys.executable).name, '-m', 'benchmarks.sweep', *sys.argv[1:]]),
        'date': datetime.datetime.now().astimezone().isoformat(timespec='seconds'),
        'machine': environment_facts(),
        'grid': {'clients': args.clients, 'goals': args.goals, 'rates_hz': args.rates,
                 'sizes': args.sizes, 'duration_s': args.duration, 'configs': args.configs,
                 'anatomy': args.anatomy, 'guard': args.guard},
        'points': [],
    }
    points = grid(args)

    def progress(line: str) -> None:
        print(f'[{time.monotonic() - started:7.1f} s] {line}', flush=True)

    run_class = load.CapturingRun if args.anatomy else load.LoadRun
    for i, point in enumerate(points, 1):
        spec = load.LoadSpec(
            clients=point['clients'], goals=point['goals'], rate_hz=point['rate_hz'],
            order=max(1, round(args.duration * point['rate_hz'])), pad=SIZES[point['size']],
            network=args.network, drain_timeout=args.drain_timeout,
            goals_timeout=args.goals_timeout, guarded=args.guard == 'on',
            server_feedback_depth=args.server_feedback_depth, loss_percent=args.loss)
        progress(f'point {i}/{len(points)}: N={spec.clients} M={spec.goals} '
                 f'{spec.rate_hz:g} Hz {point["size"]}')
        point_started = time.monotonic()
        try:
            result = load.run_load(spec, args.configs, progress, run_class)
        except Exception as e:  # noqa: BLE001 (keep the sweep going; the failure is a result too)
            progress(f'point failed: {e}')
            result = {'spec': vars(spec).copy(), 'error': str(e), 'phases': []}
        result['size'] = point['size']
        result['elapsed_s'] = time.monotonic() - point_started
        result['load_average_at_end'] = os.getloadavg()
        results['points'].append(result)
        results['elapsed_s'] = time.monotonic() - started
        output.write_text(json.dumps(results, indent=1))
        if result['phases']:
            print(load.format_table(result), flush=True)
    progress(f'results: {output}')
    return output


# --- plots and tables -----------------------------------------------------------------------------

def _series(results: dict[str, Any], config: str, goals: int, rate: float, size: str,
            key: str) -> tuple[list[int], list[float]]:
    xs, ys = [], []
    for point in sorted(results['points'], key=lambda p: p['spec']['clients']):
        spec = point['spec']
        if (spec['goals'], spec['rate_hz'], point['size']) != (goals, rate, size):
            continue
        for phase in point['phases']:
            if phase['config'] == config and phase['summary'].get(key) is not None:
                xs.append(spec['clients'])
                ys.append(phase['summary'][key])
    return xs, ys


def plot(results: dict[str, Any], directory: Path) -> list[Path]:
    """Draw the sweep's plots into ``directory``; return their paths."""
    from harness.plot import COLOURS, pyplot
    plt = pyplot()
    directory.mkdir(parents=True, exist_ok=True)
    points = [p for p in results['points'] if p['phases'] and 'anatomy' not in p['phases'][0]]
    if not points:
        return []
    combos = sorted({(p['spec']['goals'], p['spec']['rate_hz'], p['size']) for p in points})
    configs = [c for c in load.CONFIG_LABELS
               if any(ph['config'] == c for p in points for ph in p['phases'])]
    paths = []

    panels = [('bytes_per_client', 'kB received per client', 1e-3, True),
              ('foreign_per_client', 'foreign feedback taken per client', 1, False),
              ('client_cpu_s_per_client', 'client CPU s per client', 1, False),
              ('latency_p99_ms', 'latency p99, ms', 1, True)]
    fig, axes = plt.subplots(len(combos), len(panels), figsize=(4.6 * len(panels),
                                                                 3.6 * len(combos)),
                             squeeze=False)
    for row, (goals, rate, size) in enumerate(combos):
        for col, (key, title, scale, log) in enumerate(panels):
            ax = axes[row][col]
            for config in configs:
                xs, ys = _series(results, config, goals, rate, size, key)
                if xs:
                    ax.plot(xs, [y * scale for y in ys], 'o-', color=COLOURS[config],
                            label=load.CONFIG_LABELS[config])
            ax.axvline(WRITER_FILTER_LIMIT, color='k', ls=':', lw=1)
            if log:
                ax.set_yscale('log')
            ax.set_xlabel('client processes N')
            ax.set_title(f'{title}\nM={goals}, {rate:g} Hz, {size}', fontsize=10)
            if row == 0 and col == 0:
                ax.legend(fontsize=8)
    fig.tight_layout()
    paths.append(directory / 'sweep_overview.png')
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)

    # The knee: every client's received bytes, as a fraction of what a plain client received.
    fig, axes = plt.subplots(1, len(combos), figsize=(6 * len(combos), 4.4), squeeze=False)
    for col, (goals, rate, size) in enumerate(combos):
        ax = axes[0][col]
        labelled: set[str] = set()
        for point in points:
            spec = point['spec']
            if (spec['goals'], spec['rate_hz'], point['size']) != (goals, rate, size):
                continue
            plain = next((ph for ph in point['phases'] if ph['config'] == 'rclpy'), None)
            if plain is None:
                continue
            base = plain['summary']['bytes_per_client']
            for offset, config in ((-0.8, 'client'), (0.0, 'goals'), (0.8, 'upstream')):
                phase = next((ph for ph in point['phases'] if ph['config'] == config), None)
                if phase is None:
                    continue
                key = 'rx_bytes' if point['bytes_method'] == 'netns' else 'est_bytes'
                ys = [c[key] / base for c in phase['clients']]
                ax.scatter([spec['clients'] * (1 + offset * 0.04)] * len(ys), ys, s=12,
                           alpha=0.6, color=COLOURS[config],
                           label=None if config in labelled else load.CONFIG_LABELS[config])
                labelled.add(config)
        ax.axvline(WRITER_FILTER_LIMIT, color='k', ls=':', lw=1)
        ax.axhline(1.0, color='#7f7f7f', lw=1)
        ax.text(0.99, 1.0, 'plain rclpy', fontsize=8, va='bottom', ha='right', color='#7f7f7f',
                transform=ax.get_yaxis_transform())
        ax.text(WRITER_FILTER_LIMIT, 0.02,
                ' Fast DDS: writer filters\n for 32 readers unless\n the guard raises it',
                fontsize=8, va='bottom', transform=ax.get_xaxis_transform())
        ax.set_xscale('log', base=2)
        ax.set_ylim(bottom=0)
        ax.set_xlabel('client processes N (log)')
        ax.set_ylabel('bytes received / plain rclpy\'s (per client)')
        ax.set_title(f'every client\'s received bytes, M={goals}, {rate:g} Hz, {size}',
                     fontsize=10)
        ax.legend(fontsize=8, loc='upper left')
    fig.tight_layout()
    paths.append(directory / 'sweep_knee.png')
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)
    return paths


def markdown_tables(results: dict[str, Any]) -> str:
    """One Markdown table per load point, for docs/BENCHMARKS.md."""
    out = []
    for point in results['points']:
        spec = point['spec']
        if point.get('error'):
            out.append(f"**N={spec['clients']}, M={spec['goals']}, {spec['rate_hz']:g} Hz, "
                       f"{point['size']}**: failed: {point['error']}\n")
            continue
        first = point['phases'][0]['summary']
        out.append(f"**N={spec['clients']}, M={spec['goals']}, {spec['rate_hz']:g} Hz, "
                   f"{point['size']}** ({first['all_feedback']} feedback messages per "
                   f"configuration, {spec['order']} per goal)\n")
        out.append('| configuration | own/client | foreign/client | kB rx/client (min–max) | '
                   'rx/own | client CPU s | upd/goal | p50 ms | p99 ms | Hz | bytes× | CPU× |')
        out.append('|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|')
        for phase in point['phases']:
            s = phase['summary']
            r = s.get('ratio_to_plain') or {}
            out.append(
                f"| {load.CONFIG_LABELS[phase['config']]} | {s['own_per_client']:.0f} | "
                f"{s['foreign_per_client']:.0f} | {s['bytes_per_client'] / 1e3:.0f} "
                f"({s['bytes_per_client_min'] / 1e3:.0f}–"
                f"{s['bytes_per_client_max'] / 1e3:.0f}) | "
                f"{fmt(s.get('bytes_to_own_feedback'), '.1f')} | {s['client_cpu_s']:.2f} | "
                f"{s['updates_per_goal']:.2f} | {fmt(s['latency_p50_ms'], '.1f')} | "
                f"{fmt(s['latency_p99_ms'], '.1f')} | {fmt(s['achieved_rate_hz'], '.0f')} | "
                f"{fmt(r.get('bytes'), '.3f')} | "
                f"{fmt(r.get('cpu'), '.2f')} |")
        out.append('')
        for phase in point['phases']:
            if 'anatomy' in phase:
                out.append(anatomy_table(phase))
    return '\n'.join(out)


def anatomy_table(phase: dict[str, Any]) -> str:
    """The byte breakdown of one captured client, as a Markdown table."""
    from harness.capture import CATEGORIES
    own_payload = phase['clients'][0]['own'] * phase['summary']['feedback_message_bytes']
    rows = [f"*{load.CONFIG_LABELS[phase['config']]}, first client: own feedback payload "
            f"{own_payload / 1e3:.1f} kB*\n",
            '| received | kB | packets | × own payload |', '|---|---:|---:|---:|']
    total = 0
    for category in CATEGORIES:
        entry = phase['anatomy'][category]
        total += entry['bytes']
        rows.append(f"| {category} | {entry['bytes'] / 1e3:.1f} | {entry['packets']} | "
                    f"{entry['bytes'] / own_payload:.2f} |" if own_payload else '')
        if 'resent_bytes' in entry and own_payload:
            rows.append(f"| … of which resent | {entry['resent_bytes'] / 1e3:.1f} | "
                        f"{entry['resent_packets']} | {entry['resent_bytes'] / own_payload:.2f} |")
    rows.append(f"| **total** | {total / 1e3:.1f} | | {total / own_payload:.2f} |"
                if own_payload else '')
    without = total - phase['anatomy']['status']['bytes']
    rows.append(f"| total without status | {without / 1e3:.1f} | | {without / own_payload:.2f} |"
                if own_payload else '')
    return '\n'.join(rows) + '\n'


def anatomy_plot(results: dict[str, Any], directory: Path) -> list[Path]:
    """Draw each captured point's received bytes by kind, x own feedback payload, per
    configuration (the first client of each phase); return the PNG paths."""
    from harness.capture import CATEGORIES
    from harness.plot import pyplot, stacked_categories
    plt = pyplot()
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for point in results['points']:
        phases = [ph for ph in point['phases'] if 'anatomy' in ph]
        if not phases:
            continue
        spec = point['spec']
        labels, rows = [], []
        for phase in phases:
            own = phase['clients'][0]['own'] * phase['summary']['feedback_message_bytes']
            labels.append(load.CONFIG_LABELS[phase['config']].replace(' ', '\n', 1))
            rows.append({c: phase['anatomy'][c]['bytes'] / own if own else 0.0
                         for c in CATEGORIES})
        fig, ax = plt.subplots(figsize=(9, 4.8))
        stacked_categories(ax, labels, rows)
        ax.set_yscale('log' if max(sum(r.values()) for r in rows) > 20 else 'linear')
        ax.axhline(1.0, color='k', ls='--', lw=1)
        ax.set_ylabel('bytes received ÷ own feedback payload')
        size = phases[0]['summary']['feedback_message_bytes']
        ax.set_title(f"One client's received bytes by kind (captured), N={spec['clients']}, "
                     f"M={spec['goals']}, {spec['rate_hz']:g} Hz, {size} B feedback\n"
                     '(dashed: own feedback payload, the floor)', fontsize=10)
        fig.tight_layout()
        paths.append(directory / f"anatomy_n{spec['clients']}m{spec['goals']}_{point['size']}.png")
        fig.savefig(paths[-1], dpi=100)
        plt.close(fig)
    return paths


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the sweep (or redraw plots); print the result file, the tables and the plots."""
    args = parse_args(argv)
    path = args.plot_only or run(args)
    results = json.loads(path.read_text())
    print(markdown_tables(results))
    for png in anatomy_plot(results, args.plots) if args.anatomy else plot(results, args.plots):
        print(f'plot: {png}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
