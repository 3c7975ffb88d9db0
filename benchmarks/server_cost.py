"""What filtered clients cost the action server: its achieved rate and CPU per message.

For every point (feedback size x N client processes, one goal each) one server runs the
configurations one after another, plain rclpy first, through the load harness of ``make demo``
(:mod:`harness.load`). Every figure is compared with the plain rclpy phase of the same server, as
a ratio:

- ``rate``: feedback messages the server published per second, from ``go`` until its last goal
  finished (the rate the server's publishing threads achieved);
- ``CPU/msg``: the server's user + system CPU seconds over the same window, per message published.

Three guard modes, each with its own servers:

- ``unguarded``: no guard, as the server of someone who only swapped a client's import: the default
  clients' filter class is unknown to it, so it filters nothing and sends as to plain clients;
- ``accelerated`` (the default guard): the guard answers uuid-only filters from the sample's UUID
  bytes (``cft_action/native/guard/_guard_filter.c``);
- ``locking``: the same guard with ``CFT_GUARD_ACCELERATE=0``: only the locks, so Fast DDS
  deserializes every sample once per filtered reader, as an unguarded server does.

With ``--rounds R`` each server runs every configuration R times, in the given order in odd rounds
and reversed in even ones (plain, cft, cft, plain, ...), so that a drift of the machine's load over
the point weighs on both alike; each phase is compared with the plain phase of its round, and the
tables give the medians over the rounds. Every phase also gives the server's system share of its
CPU per message (``sys``: the kernel's sending, and its waking of the clients' receive threads),
and counts its context switches per message (``getrusage``): ``waits`` (voluntary) and
``preempted`` (involuntary: a thread that became runnable, such as a client's receive thread woken
by a datagram, took the CPU).

A phase whose goals do not finish within ``--phase-timeout`` seconds is cut there; its rate is what
was published until then, and the rest of that point's phases run against a fresh server.
``--security ENCRYPT`` (or ``SIGN``) runs every process with DDS Security (SROS2), Enforce, in one
enclave of a keystore made for the run (:class:`harness.keystore.Keystore`), whose governance
protects discovery, liveliness, whole messages, submessages and payloads at that kind: plain rclpy
and the library under the same governance. ``--network netns`` counts each client's received bytes
on its own interface (``bytes``, a ratio to plain's too) instead of estimating them.
``--server-cpus 0 --client-cpus 1`` keeps the server and its clients on separate CPUs, as when the
clients run on other machines: a client woken by a datagram then cannot preempt the server.

Results (machine, date, command, every raw figure) go to
``benchmarks/results/server-cost-<date>-<host>.json`` after every point; ``--plot`` draws
``docs/img/server_cost.png``. Run from the repository's root::

    python -m benchmarks.server_cost --sizes 36B,1k,10k --clients 1,4,16,32
    python -m benchmarks.server_cost --guards unguarded --configs rclpy,client --rounds 6 \\
        --sizes 36B,1k --clients 8,32 --duration 3
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Optional, Sequence

from harness import load
from harness.keystore import PROTECTIONS, Keystore
from harness.proc import add_cpu_arguments
from harness.machine import environment_facts
from harness.report import fmt, grid, markdown_table

REPO = Path(__file__).resolve().parent.parent
#: int32 elements after the 3-element header: 36 B, 1 kB and 10 kB feedback messages.
SIZES = {'36B': 0, '1k': 250, '10k': 2500}
#: guard mode -> (under the guard, the server's extra environment)
GUARD_MODES: dict[str, tuple[bool, dict[str, str]]] = {
    'unguarded': (False, {}), 'accelerated': (True, {}),
    'locking': (True, {'CFT_GUARD_ACCELERATE': '0'})}


class CappedRun(load.LoadRun):
    """A load run whose phases stop waiting for their goals after a fixed time."""

    phase_timeout = 120.0

    def _wait_for_goals(self, before: dict[str, Any]) -> dict[str, Any]:
        deadline = time.monotonic() + self.phase_timeout
        while True:
            stats = self.server_stats()
            if (stats['accepted'] - before['accepted'] >= self.spec.total_goals
                    and stats['active'] == 0):
                return {**stats, 'timed_out': False}
            if time.monotonic() > deadline:
                return {**stats, 'timed_out': True}
            time.sleep(0.1)


class ProfiledRun(CappedRun):
    """A capped run that samples the server with ``perf record`` while the goals of a phase run."""

    profile_dir = Path('.')

    def window_started(self, clients: list[Any], server_stats: dict[str, Any]) -> None:
        runs = len(list(self.profile_dir.glob('perf-*')))
        self.perf_data = self.profile_dir / f'perf-{runs}.data'
        self.perf = subprocess.Popen(['perf', 'record', '-F', '1999', '-g',
                                      '-p', str(self.server.pid), '-o', str(self.perf_data)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def window_ended(self, clients: list[Any]) -> dict[str, Any]:
        self.perf.send_signal(signal.SIGINT)
        self.perf.wait(timeout=60)
        report = subprocess.run(['perf', 'report', '-i', str(self.perf_data), '--no-children',
                                 '--sort', 'dso,symbol', '--stdio', '-g', 'none',
                                 '--percent-limit', '1.5'],
                                capture_output=True, text=True, timeout=300).stdout
        by_library = subprocess.run(['perf', 'report', '-i', str(self.perf_data), '--no-children',
                                     '--sort', 'dso', '--stdio', '-g', 'none'],
                                    capture_output=True, text=True, timeout=300).stdout
        return {'profile': _perf_rows(report)[:25],
                'profile_by_library': _perf_rows(by_library)[:12], 'perf_data': str(self.perf_data)}


def _perf_rows(report: str) -> list[str]:
    return [' '.join(line.split()) for line in report.splitlines()
            if line.strip() and not line.startswith('#')]


def per_message(phase: dict[str, Any], counter: str) -> Optional[float]:
    """The server's context switches of kind ``counter`` over the phase's goals, per message."""
    count = phase.get('server_switches_goals', {}).get(counter)
    if count is None or not phase['published_at_goals']:
        return None
    return count / phase['published_at_goals']


def phase_figures(phase: dict[str, Any]) -> dict[str, Any]:
    """Rate and CPU per message of one phase, from the server's counters at its last goal."""
    summary = phase['summary']
    return {
        'config': phase['config'],
        'published': phase['published_at_goals'],
        'goals_s': phase['goals_s'],
        'timed_out': phase['timed_out'],
        'rate_msgs_per_s': summary['server_msgs_per_s'],
        'rate_per_goal_hz': summary['achieved_rate_hz'],
        'server_cpu_s': phase['server_cpu_goals_s'],
        'cpu_ms_per_msg': summary['server_cpu_ms_per_msg'],
        'sys_ms_per_msg': (1000 * phase['server_sys_goals_s'] / phase['published_at_goals']
                           if phase.get('server_sys_goals_s') is not None
                           and phase['published_at_goals'] else None),
        'waits_per_msg': per_message(phase, 'switches'),
        'preempted_per_msg': per_message(phase, 'preempted'),
        'server_requests': phase.get('server_requests_goals', {}),
        'clients_cpu_ms_per_msg': (1000 * summary['client_cpu_s'] / phase['published']
                                   if phase['published'] else None),
        'own_per_client': summary['own_per_client'],
        'bytes_per_client': summary['bytes_per_client'],
        'bytes_method': summary['bytes_method'],
        'foreign_per_client': summary['foreign_per_client'],
        'guard_filter': phase.get('guard_filter', {}),
        **{k: phase[k] for k in ('profile', 'profile_by_library') if k in phase},
    }


def run_point(spec: load.LoadSpec, configs: Sequence[str], timeout: float,
              progress: load.Progress, profile_dir: Optional[Path] = None, rounds: int = 1
              ) -> list[dict[str, Any]]:
    """Run ``configs`` under ``spec``, ``rounds`` times; a fresh server after any phase that was
    cut. Each phase's ratios refer to the plain phase of its round."""
    figures: list[dict[str, Any]] = []
    pending = load.round_order(configs, rounds)
    while pending:
        run = CappedRun(spec, progress) if profile_dir is None else ProfiledRun(spec, progress)
        run.phase_timeout = timeout
        if profile_dir is not None:
            run.profile_dir = profile_dir
        try:
            while pending:
                round_number, config = pending.pop(0)
                try:
                    phase = run.run_phase(config)
                except (TimeoutError, RuntimeError) as failure:  # a client or the server failed
                    progress(f'    {config} failed: {str(failure).splitlines()[0]}')
                    figures.append({'config': config, 'round': round_number,
                                    'error': str(failure)[:2000]})
                    break
                figures.append({**phase_figures(phase), 'round': round_number})
                if phase['timed_out']:
                    progress(f'    cut after {timeout:.0f} s: {phase["published_at_goals"]} '
                             'published; next configuration on a fresh server')
                    break
        finally:
            run.close()
    for f in figures:
        if 'error' in f:
            continue
        plain = next((p for p in figures if p['config'] == 'rclpy' and 'error' not in p
                      and p['round'] == f['round']), None)
        f['ratio_to_plain'] = {
            'rate': ratio(f['rate_msgs_per_s'], plain and plain['rate_msgs_per_s']),
            'cpu_per_msg': ratio(f['cpu_ms_per_msg'], plain and plain['cpu_ms_per_msg']),
            'bytes': ratio(f['bytes_per_client'], plain and plain['bytes_per_client']),
        }
    return figures


def _median(values: Sequence[Optional[float]]) -> Optional[float]:
    present = [v for v in values if v is not None]
    return statistics.median(present) if present else None


def medians(figures: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per configuration, the medians of its phases' figures over the rounds, their ratios to
    plain's medians, and each round's CPU ratio (``round_cpu_ratios``)."""
    out: dict[str, dict[str, Any]] = {}
    for config in dict.fromkeys(f['config'] for f in figures):
        mine = [f for f in figures if f['config'] == config and 'error' not in f]
        out[config] = {
            'phases': len(mine), 'cut': sum(f['timed_out'] for f in mine),
            **{key: _median([f[key] for f in mine])
               for key in ('rate_msgs_per_s', 'cpu_ms_per_msg', 'waits_per_msg',
                           'preempted_per_msg', 'clients_cpu_ms_per_msg')},
            'round_cpu_ratios': [f['ratio_to_plain']['cpu_per_msg'] for f in mine]}
    plain = out.get('rclpy', {})
    for m in out.values():
        m['ratio_to_plain'] = {'rate': ratio(m['rate_msgs_per_s'], plain.get('rate_msgs_per_s')),
                               'cpu_per_msg': ratio(m['cpu_ms_per_msg'],
                                                    plain.get('cpu_ms_per_msg'))}
    return out


def ratio(value: Optional[float], reference: Optional[float]) -> Optional[float]:
    return value / reference if value is not None and reference else None


def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument('--sizes', default='36B,1k,10k', help='from: ' + ', '.join(SIZES))
    parser.add_argument('--clients', default='1,4,16,32', help='N, comma-separated')
    parser.add_argument('--guards', default='unguarded,accelerated',
                        help='guard modes, from: ' + ', '.join(GUARD_MODES))
    parser.add_argument('--configs', default='rclpy,client,goals,upstream',
                        help='from: ' + ', '.join(load.CONFIG_LABELS) + ' (rclpy first)')
    parser.add_argument('--rate', type=float, default=100.0, help='feedback Hz per goal')
    parser.add_argument('--duration', type=float, default=2.0,
                        help='nominal seconds of feedback per goal')
    parser.add_argument('--rounds', type=int, default=1,
                        help='phases of each configuration per server, the order reversed in '
                             'even rounds')
    parser.add_argument('--phase-timeout', type=float, default=90.0,
                        help='seconds a phase may wait for its goals before it is cut')
    parser.add_argument('--security', choices=PROTECTIONS, default=None,
                        help='every process with DDS Security, everything protected at this kind')
    parser.add_argument('--network', choices=('count', 'netns'), default='count',
                        help='clients\' bytes: estimated, or received on their own interfaces')
    add_cpu_arguments(parser)
    parser.add_argument('--drain-timeout', type=float, default=300.0,
                        help='seconds the clients may take the rest of a phase\'s feedback after '
                             'its goals (plain clients fall far behind at N = 32); the server\'s '
                             'figures end at its last goal')
    parser.add_argument('--output', type=Path, default=None)
    parser.add_argument('--plot', type=Path, default=None, metavar='PNG',
                        help='also draw the rate ratios into this file')
    parser.add_argument('--markdown', type=Path, default=None, metavar='RESULTS',
                        help='only print the Markdown tables (and draw --plot) of a results file')
    parser.add_argument('--profile', type=Path, default=None, metavar='DIR',
                        help='sample the server with perf record during each phase\'s goals, '
                             'keep perf-N.data in DIR, and add the top symbols to the results')
    args = parser.parse_args(argv)
    args.sizes = [s for s in args.sizes.split(',') if s]
    args.clients = [int(n) for n in args.clients.split(',') if n]
    args.guards = [g for g in args.guards.split(',') if g]
    args.configs = [c for c in args.configs.split(',') if c]
    for name, values, known in (('--sizes', args.sizes, SIZES), ('--guards', args.guards,
                                                                  GUARD_MODES),
                                ('--configs', args.configs, load.CONFIG_LABELS)):
        unknown = set(values) - set(known)
        if unknown:
            parser.error(f'{name}: unknown {", ".join(sorted(unknown))}')
    if args.configs[0] != 'rclpy':
        parser.error('--configs must start with rclpy: every ratio refers to it')
    return args


def format_table(points: list[dict[str, Any]]) -> str:
    rows = [('guard', 'size', 'N', 'round', 'configuration', 'msgs', 'goals s', 'msgs/s',
             'rate x plain', 'CPU ms/msg', 'CPU x plain', 'sys ms/msg', 'waits/msg',
             'preempted/msg',
             'kB/client', 'bytes x plain', 'guard verdicts', 'Fast DDS verdicts')]
    for point in points:
        for f in point['figures']:
            head = (point['guard'], point['size'], str(point['clients']), str(f.get('round', 1)))
            if 'error' in f:
                rows.append((*head, load.CONFIG_LABELS[f['config']] + ' (failed)', *['-'] * 13))
                continue
            r = f['ratio_to_plain']
            gf = f['guard_filter']
            label = load.CONFIG_LABELS[f['config']] + (' (cut)' if f['timed_out'] else '')
            rows.append((*head, label,
                         str(f['published']), fmt(f['goals_s'], '.1f'),
                         fmt(f['rate_msgs_per_s'], '.0f'), fmt(r['rate'], '.2f'),
                         fmt(f['cpu_ms_per_msg'], '.3f'), fmt(r['cpu_per_msg'], '.2f'),
                         fmt(f.get('sys_ms_per_msg'), '.3f'),
                         fmt(f.get('waits_per_msg'), '.2f'), fmt(f.get('preempted_per_msg'), '.2f'),
                         fmt(_kb(f.get('bytes_per_client')), '.1f'), fmt(r.get('bytes'), '.2f'),
                         _verdicts(gf, 'uuid_verdicts', 'relevance_verdicts'),
                         _verdicts(gf, 'fastdds_verdicts')))
    return grid(rows)


def _verdicts(counters: dict[str, Any], *names: str) -> str:
    """The sum of the guard's counters ``names`` (:func:`cft_action.guard.filter_counts`),
    or '-' where the phase reports none of them."""
    found = [counters[n] for n in names if n in counters]
    return str(sum(found)) if found else '-'


def _kb(octets: Optional[float]) -> Optional[float]:
    return None if octets is None else octets / 1000


def _range(values: list[Optional[float]]) -> str:
    present = [v for v in values if v is not None]
    return f' ({min(present):.2f}-{max(present):.2f})' if len(present) > 1 else ''


def markdown(points: list[dict[str, Any]]) -> str:
    """One Markdown table per guard mode: rate and CPU per message as ratios to plain rclpy, the
    medians over the rounds (with the range of the rounds' CPU ratios when there are several)."""
    out = []
    for guard_mode in GUARD_MODES:
        mine = [p for p in points if p['guard'] == guard_mode]
        if not mine:
            continue
        configs = [c for c in dict.fromkeys(f['config'] for f in mine[0]['figures'])
                   if c != 'rclpy']
        head = ['feedback', 'N', 'plain: msgs/s, CPU ms/msg, preempted/msg']
        head += [f'{load.CONFIG_LABELS[c]}: rate, CPU/msg, preempted/msg' for c in configs]
        out += [f'Guard {guard_mode}: ratios to plain rclpy (rate: higher is better; CPU per '
                'message: lower is better; medians over the rounds, and the range of the rounds\' '
                'CPU ratios; preempted/msg: the server\'s involuntary context switches per '
                'message; "cut": the goals had not finished after the phase timeout, the rate is '
                'what was published until then)', '']
        rows = []
        for p in mine:
            by = p.get('medians') or medians(p['figures'])
            plain = by.get('rclpy', {})
            row = [f"{p['size']} ({p['feedback_bytes']} B)", str(p['clients']),
                   f"{fmt(plain.get('rate_msgs_per_s'), '.0f')}, "
                   f"{fmt(plain.get('cpu_ms_per_msg'), '.3f')}, "
                   f"{fmt(plain.get('preempted_per_msg'), '.2f')}"]
            for c in configs:
                m = by.get(c)
                if not m or not m['phases']:
                    row.append('failed' if m else '-')
                    continue
                r = m['ratio_to_plain']
                row.append(f"{fmt(r['rate'], '.2f')}, {fmt(r['cpu_per_msg'], '.2f')}"
                           f"{_range(m['round_cpu_ratios'])}, "
                           f"{fmt(m.get('preempted_per_msg'), '.2f')}"
                           + (' (cut)' if m['cut'] else ''))
            rows.append(row)
        out += [*markdown_table(head, rows), '']
    return '\n'.join(out)


def plot(points: list[dict[str, Any]], path: Path) -> None:
    """Rate ratio to plain rclpy against N, one panel per guard mode and size."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    guards = sorted({p['guard'] for p in points}, key=list(GUARD_MODES).index)
    sizes = sorted({p['size'] for p in points}, key=list(SIZES).index)
    fig, axes = plt.subplots(len(guards), len(sizes), figsize=(4.2 * len(sizes), 3.4 * len(guards)),
                             squeeze=False, sharex=True)
    for gi, guard_mode in enumerate(guards):
        for si, size in enumerate(sizes):
            ax = axes[gi][si]
            mine = [p for p in points if p['guard'] == guard_mode and p['size'] == size]
            if not mine:
                ax.text(0.5, 0.5, 'not measured in this run', ha='center', va='center',
                        transform=ax.transAxes)
            configs = [f['config'] for f in mine[0]['figures']] if mine else []
            for config in configs:
                xs, ys = [], []
                for p in sorted(mine, key=lambda p: p['clients']):
                    f = next((f for f in p['figures'] if f['config'] == config), None)
                    if f and f.get('ratio_to_plain', {}).get('rate') is not None:
                        xs.append(p['clients'])
                        ys.append(f['ratio_to_plain']['rate'])
                ax.plot(xs, ys, marker='o', label=load.CONFIG_LABELS[config])
            ax.axhline(0.9, color='grey', linestyle=':', linewidth=1)
            ax.set_xscale('log', base=2)
            ax.set_yscale('log')
            ax.set_title(f'{size} feedback, guard {guard_mode}', fontsize=10)
            ax.set_xlabel('client processes N (1 goal each)')
            ax.set_ylabel('server msgs/s ÷ plain rclpy')
            ax.grid(True, which='both', alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.suptitle('Server publishing rate with filtered clients, relative to plain clients '
                 '(dotted: 0.9)', fontsize=11)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = parse_args(argv)
    if args.markdown:
        points = json.loads(args.markdown.read_text())['points']
        print(markdown(points))
        if args.plot:
            plot(points, args.plot)
        return 0
    started = datetime.datetime.now(datetime.timezone.utc)
    output = args.output or (REPO / 'benchmarks' / 'results' /
                             f'server-cost-{started.date().isoformat()}-{platform.node()}.json')
    order = max(1, round(args.duration * args.rate))
    result: dict[str, Any] = {
        'benchmark': 'server_cost', 'started': started.isoformat(timespec='seconds'),
        'command': 'python -m benchmarks.server_cost ' + ' '.join(sys.argv[1:] if argv is None
                                                                 else argv),
        'machine': environment_facts(), 'order': order, 'rate_hz': args.rate,
        'security': args.security, 'network': args.network, 'points': []}
    if args.security:  # inherited by the server and every client (harness.load copies os.environ)
        keystore = Keystore(Path(tempfile.mkdtemp(prefix='cft-keystore-')), args.security)
        os.environ.update(keystore.enclave('/cft/bench'))
    total = len(args.guards) * len(args.sizes) * len(args.clients)
    t0 = time.monotonic()

    def progress(line: str) -> None:
        print(f'[{time.monotonic() - t0:6.0f} s] {line}', flush=True)

    done = 0
    for guard_mode in args.guards:
        for size in args.sizes:
            for n in args.clients:
                done += 1
                progress(f'point {done}/{total}: guard {guard_mode}, {size} feedback, N = {n}')
                spec = load.LoadSpec(clients=n, goals=1, order=order, rate_hz=args.rate,
                                         pad=SIZES[size], network=args.network, settle_s=2.0,
                                         drain_timeout=args.drain_timeout,
                                         guarded=GUARD_MODES[guard_mode][0],
                                         server_env=GUARD_MODES[guard_mode][1],
                                         server_cpus=args.server_cpus,
                                         client_cpus=args.client_cpus)
                if args.profile:
                    args.profile.mkdir(parents=True, exist_ok=True)
                figures = run_point(spec, args.configs, args.phase_timeout, progress,
                                    args.profile, args.rounds)
                result['points'].append({'guard': guard_mode, 'size': size, 'clients': n,
                                         'feedback_bytes': load.feedback_size(SIZES[size]),
                                         'figures': figures, 'medians': medians(figures),
                                         'load_average': os.getloadavg()})
                output.parent.mkdir(parents=True, exist_ok=True)
                output.write_text(json.dumps(result, indent=1))
                print(format_table(result['points'][-1:]), flush=True)
                for f in figures:
                    if f.get('profile'):
                        print(f"perf, {f['config']}:", *f['profile_by_library'], *f['profile'][:15],
                              sep='\n  ', flush=True)
    result['finished'] = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')
    output.write_text(json.dumps(result, indent=1))
    print('\n' + format_table(result['points']))
    print('\n' + markdown(result['points']))
    print(f'\nresults: {output}')
    if args.plot:
        plot(result['points'], args.plot)
        print(f'plot: {args.plot}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
