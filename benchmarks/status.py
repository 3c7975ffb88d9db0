"""The action status topic: what it costs each client as clients, goals and result_timeout grow.

An action server publishes ``<action>/_action/status`` (``action_msgs/GoalStatusArray``) at every
goal state change (accepted, executing, succeeded: three per goal in rclpy), and each message lists
every goal the server holds: the running ones, and the finished ones until the server's
``result_timeout`` (900 s by default in rclpy) expires them. Every client receives every message,
whatever its feedback filter: DDS-SQL filters cannot pick entries out of a sequence, and one sample
lists all goals. So a client's status bytes grow with the square of the goals.

Two parts, both through the load harness of ``make demo`` (:mod:`harness.load`), with a packet
capture on the first client of every phase (:class:`harness.load.CapturingRun`,
``harness/capture.py``) and every client counting the status messages it takes and their
serialized size (:mod:`harness.client`):

- ``grid``: N client processes x M goals each, all sent at once, for each configuration (plain
  rclpy and ``client`` mode by default), the server keeping finished goals 2 s;
- ``timeouts``: goals arriving over time (``--arrivals CLIENTS,GOALS,INTERVAL``: each client
  sends a goal every INTERVAL seconds), against servers with each ``result_timeout`` in turn, so
  that finished goals accumulate.

Before ``go`` a phase waits until the clients' probe goals (:mod:`harness.client`) have expired
(when ``result_timeout`` is at most :data:`PROBE_WAIT_MAX_S`), so the window starts with an empty
status list. Next to each measurement stands the model of
:func:`harness.status_model.predict`: three status messages per goal, each of
:func:`harness.status_model.wire_bytes` for the goals held at that moment.

Results (machine, date, command, versions, load averages, every raw figure) go to
``benchmarks/results/status-<date>-<host>.json`` after every point; the tables are printed as
Markdown and the plot goes to ``docs/img/status_bytes.png``. Run from the repository's root, as
root (network namespaces)::

    python -m benchmarks.status --parts grid --clients 1,4,16,32 --goals 1,4,16
    python -m benchmarks.status --parts timeouts --timeouts 2,10,60,900
    python -m benchmarks.status --report RESULTS.json [MORE.json ...]
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

from harness import load
from harness.cli import int_list, name_list
from harness.machine import environment_facts
from harness.proc import Proc
from harness.report import fmt, markdown_table
from harness.status_model import (INFO_DST, MESSAGES_PER_GOAL, STATUS_ENTRY, WIRE_OVERHEAD,
                                   entries_in, predict)

REPO = Path(__file__).resolve().parent.parent

#: The grid's server kinds: under ``cft-action guard`` or not.
SERVERS = {'guarded': 'under cft-action guard', 'unguarded': 'without the guard'}

#: Longest wait for the probe goals to expire before a phase's ``go``: with a longer
#: result_timeout they stay, and the model counts them as held.
PROBE_WAIT_MAX_S = 10


class StatusRun(load.CapturingRun):
    """A capturing load run whose phases start once the probe goals have expired."""

    def window_started(self, clients: list[Proc], server_stats: dict[str, Any]) -> None:
        """Wait out the probes' result_timeout (up to :data:`PROBE_WAIT_MAX_S`), then capture."""
        self._requests = {k: server_stats[k] for k in ('goal_requests', 'goal_responses',
                                                       'goal_response_errors', 'accepted')}
        if self.spec.result_timeout_s <= PROBE_WAIT_MAX_S:
            time.sleep(self.spec.result_timeout_s + 0.5)
        self._window_t = time.monotonic()
        super().window_started(clients, server_stats)

    def window_ended(self, clients: list[Proc]) -> dict[str, Any]:
        """The capture's counts, the server's goal-request counters before ``go``, and when the
        server took each goal request of the window (s after the first; the same monotonic clock
        in every process)."""
        takes = [t for _, t in self.server.request_json('takes', 'TAKES')
                 if t >= self._window_t]
        return {**super().window_ended(clients), 'server_before_go': self._requests,
                'accept_times': [t - min(takes) for t in sorted(takes)]}


def _arrivals(text: str) -> tuple[int, int, float]:
    """``CLIENTS,GOALS,INTERVAL`` (an argparse type)."""
    clients, goals, interval = text.split(',')
    return int(clients), int(goals), float(interval)


def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument('--parts', default='grid,timeouts',
                        help='comma-separated: grid (N x M), timeouts (result_timeout)')
    parser.add_argument('--clients', type=int_list, default=[1, 4, 16, 32],
                        help='grid: client processes N')
    parser.add_argument('--goals', type=int_list, default=[1, 4, 16],
                        help='grid: goals per client M')
    parser.add_argument('--configs', type=name_list(load.CONFIG_LABELS),
                        default=['rclpy', 'client'],
                        help='grid: comma-separated, from: ' + ', '.join(load.CONFIG_LABELS))
    parser.add_argument('--servers', type=name_list(SERVERS), default=['guarded'],
                        help='grid: comma-separated server kinds, from: ' + ', '.join(SERVERS))
    parser.add_argument('--timeouts', type=int_list, default=[2, 10, 60, 900],
                        help='timeouts: the server\'s result_timeout values, s')
    parser.add_argument('--timeout-configs', type=name_list(load.CONFIG_LABELS), default=['client'],
                        help='timeouts: comma-separated configurations')
    parser.add_argument('--arrivals', type=_arrivals, default=(2, 120, 1.0),
                        metavar='CLIENTS,GOALS,INTERVAL',
                        help='timeouts: client processes, goals per client, seconds between them')
    parser.add_argument('--rate', type=float, default=5.0, help='feedback per second per goal')
    parser.add_argument('--duration', type=float, default=1.0, help='seconds a goal runs')
    parser.add_argument('--goals-timeout', type=float, default=None,
                        help='seconds the goals of a phase may take (default: harness.load\'s)')
    parser.add_argument('--output', type=Path, default=None,
                        help='results file (default: benchmarks/results/status-<date>-<host>.json)')
    parser.add_argument('--plot', type=Path, default=REPO / 'docs' / 'img' / 'status_bytes.png')
    parser.add_argument('--report', type=Path, nargs='+', default=None, metavar='RESULTS',
                        help='only print the tables and draw the plot of results files')
    args = parser.parse_args(argv)
    args.parts = [p.strip() for p in args.parts.split(',') if p.strip()]
    if set(args.parts) - {'grid', 'timeouts'}:
        parser.error('--parts: grid, timeouts')
    return args


def points(args: argparse.Namespace) -> list[tuple[str, load.LoadSpec, list[str]]]:
    """(part, spec, configurations) of every point: the grid cheapest first, then the timeouts."""
    order = max(1, round(args.duration * args.rate))
    common = {'order': order, 'rate_hz': args.rate, 'network': 'netns', 'settle_s': 3.0,
              'goals_timeout': args.goals_timeout}
    out: list[tuple[str, load.LoadSpec, list[str]]] = []
    if 'grid' in args.parts:
        grid = sorted(((n, m) for n in args.clients for m in args.goals),
                      key=lambda nm: (nm[0] * nm[1]) ** 2 * nm[0])
        out += [('grid', load.LoadSpec(clients=n, goals=m, guarded=server == 'guarded',
                                       **common), args.configs)
                for n, m in grid for server in args.servers]
    if 'timeouts' in args.parts:
        clients, goals, interval = args.arrivals
        out += [('timeouts', load.LoadSpec(clients=clients, goals=goals, result_timeout_s=t,
                                           goal_interval_s=interval, **common),
                 args.timeout_configs)
                for t in args.timeouts]
    return out


def model_for(spec: dict[str, Any], held_at_go: Optional[int] = None,
              goals_s: Optional[float] = None,
              accept_times: Optional[Sequence[float]] = None,
              period_s: Optional[float] = None) -> dict[str, float]:
    """The model's figures for a load point (a :class:`harness.load.LoadSpec` as a dict).

    ``held_at_go``: the goals the server held at ``go``, as measured; None: the clients' probes
    when the phase did not wait for them to expire, else none. Measured ones that outlived the
    wait for the probes stay held through the window. ``goals_s``: the measured seconds from
    ``go`` until the last goal finished; with goals sent over time, their interval is taken from
    it (a client's timer runs a little slower than its period on a loaded machine), else from the
    spec. ``accept_times``: when the server took each goal request, measured; they replace the
    schedule (the spec's: all at once, or one per interval per client). ``period_s``: the
    feedback period the server achieved, measured; a goal's life is taken from it (a loaded
    server ticks late), else from the spec's rate.
    """
    timeout = spec['result_timeout_s']
    # The ticker finishes a goal at its order-th tick after the first feedback: the first tick
    # comes 0 to 1 period after acceptance, so a goal lasts (order - 0.5) periods on average.
    duration = (spec['order'] - 0.5) * (period_s or 1.0 / spec['rate_hz'])
    interval = spec['goal_interval_s']
    if interval and goals_s is not None and spec['goals'] > 1:
        interval = (goals_s - duration) / (spec['goals'] - 1)
    # Every client sends its k-th goal at k x interval (all at 0 without an interval).
    accepted = list(accept_times) if accept_times else [
        k * interval for k in range(spec['goals']) for _ in range(spec['clients'])]
    waited = timeout <= PROBE_WAIT_MAX_S
    if held_at_go is None:
        held_at_go = 0 if waited else spec['clients']
    held_s = math.inf if waited else timeout
    return predict(accepted, duration, timeout, held_at_go, held_s, spec['clients'])


def figures(phase: dict[str, Any], readers: int) -> dict[str, Any]:
    """The status figures of one phase: the captured first client, and the mean over clients."""
    anatomy = phase['anatomy']
    captured_total = sum(v['bytes'] for v in anatomy.values())
    status = anatomy['status']
    datagrams = status.get('datagrams') or [0]
    # The first sample of the window is the first goal's acceptance: what else it lists was held.
    held_at_go = max(0, round(entries_in(datagrams[0], readers)) - 1)
    feedback = anatomy['feedback data']['bytes'] + anatomy['feedback gap/heartbeat']['bytes']
    first = phase['clients'][0]
    clients = phase['clients']
    return {
        'status_bytes': status['bytes'], 'status_packets': status['packets'],
        'status_samples': status['samples'], 'captured_bytes': captured_total,
        'status_share': status['bytes'] / captured_total if captured_total else None,
        'feedback_share': feedback / captured_total if captured_total else None,
        'wire_bytes_per_sample': status['bytes'] / status['samples'] if status['samples'] else None,
        'datagram_mean': statistics.fmean(datagrams), 'datagram_max': max(datagrams),
        'entries_per_sample': entries_in(statistics.fmean(datagrams), readers),
        'max_entries_wire': entries_in(max(datagrams), readers),
        'held_at_go': held_at_go,
        'first_rx_bytes': first.get('rx_bytes'),
        'first_status_taken': first['status'], 'first_status_cdr_bytes': first['status_cdr_bytes'],
        'status_taken_per_client': statistics.fmean(c['status'] for c in clients),
        'status_taken_min': min(c['status'] for c in clients),
        'status_cdr_bytes_per_client': statistics.fmean(c['status_cdr_bytes'] for c in clients),
        'entries_per_message': (first['status_entries'] / first['status']
                                if first['status'] else None),
        'max_entries': max(c['status_max_entries'] for c in clients),
        'rx_bytes_per_client': statistics.fmean(c.get('rx_bytes', 0) for c in clients),
        'client_cpu_s_per_client': phase['summary']['client_cpu_s_per_client'],
    }


def analyse(point: dict[str, Any]) -> dict[str, Any]:
    """Add the status figures and the model to a point and its phases, from their raw figures."""
    for phase in point['phases']:
        phase['status'] = figures(phase, point['spec']['clients'])
        phase['model_schedule'] = model_for(point['spec'], phase['status']['held_at_go'],
                                            phase['goals_s'])
        achieved = phase['interval_s'] / phase['intervals'] if phase['intervals'] else None
        phase['model'] = model_for(point['spec'], phase['status']['held_at_go'],
                                   phase['goals_s'], phase.get('accept_times'), achieved)
    point['model'] = model_for(point['spec'])
    return point


def run(args: argparse.Namespace) -> Path:
    """Measure every point, writing the results file after each; return its path."""
    today = datetime.date.today().isoformat()
    output = args.output or (REPO / 'benchmarks' / 'results' /
                             f'status-{today}-{platform.node()}.json')
    output.parent.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    results: dict[str, Any] = {
        'benchmark': 'status',
        'command': ' '.join(['python', '-m', 'benchmarks.status', *sys.argv[1:]]),
        'date': datetime.datetime.now().astimezone().isoformat(timespec='seconds'),
        'machine': environment_facts(),
        'model': {'messages_per_goal': MESSAGES_PER_GOAL, 'wire_overhead': WIRE_OVERHEAD,
                  'info_dst_single_reader': INFO_DST, 'status_entry_bytes': STATUS_ENTRY},
        'points': [],
    }

    def progress(line: str) -> None:
        print(f'[{time.monotonic() - started:7.1f} s] {line}', flush=True)

    todo = points(args)
    for i, (part, spec, configs) in enumerate(todo, 1):
        progress(f'point {i}/{len(todo)} ({part}, {"" if spec.guarded else "un"}guarded): '
                 f'N={spec.clients} M={spec.goals} '
                 f'result_timeout={spec.result_timeout_s} s interval={spec.goal_interval_s:g} s; '
                 f'load average {os.getloadavg()[0]:.2f}')
        point: dict[str, Any] = {'part': part, 'load_average_start': os.getloadavg()}
        point_started = time.monotonic()
        try:
            point.update(load.run_load(spec, configs, progress, StatusRun))
        except Exception as e:  # noqa: BLE001 (keep going; the failure is a result too)
            progress(f'point failed: {e}')
            point.update({'spec': vars(spec).copy(), 'error': str(e), 'phases': []})
        analyse(point)
        point['load_average_end'] = os.getloadavg()
        point['elapsed_s'] = time.monotonic() - point_started
        results['points'].append(point)
        results['elapsed_s'] = time.monotonic() - started
        output.write_text(json.dumps(results, indent=1))
        print(markdown([point]), flush=True)
    progress(f'results: {output}')
    return output


# --- tables and plot ------------------------------------------------------------------------------

#: A table column: its header, and its cell from a point and one of its phases.
Column = tuple[str, Callable[[dict[str, Any], dict[str, Any]], str]]


def _figure(key: str, spec: str, scale: float = 1.0) -> Callable[[dict[str, Any],
                                                                   dict[str, Any]], str]:
    """A cell of the phase's status figures (``key``), scaled and formatted."""
    def cell(point: dict[str, Any], phase: dict[str, Any]) -> str:
        value = phase['status'][key]
        return fmt(value * scale if value is not None and scale != 1.0 else value, spec)
    return cell


def _vs(model: str) -> Callable[[dict[str, Any], dict[str, Any]], str]:
    """A cell: measured status bytes over the phase's ``model``."""
    def cell(point: dict[str, Any], phase: dict[str, Any]) -> str:
        return f"{phase['status']['status_bytes'] / phase[model]['wire_bytes']:.2f}"
    return cell


_CONFIG: Column = ('configuration', lambda p, ph: load.phase_label(ph))
_GOALS: Column = ('goals', lambda p, ph: str(p['spec']['clients'] * p['spec']['goals']))
_STATUS: list[Column] = [
    ('status kB/client', _figure('status_bytes', '.1f', 1e-3)),
    ('samples', _figure('status_samples', 'd')),
    ('status share', _figure('status_share', '.0%')),
]
_SCHEDULE: list[Column] = [
    ('model kB, schedule', lambda p, ph: f"{ph['model_schedule']['wire_bytes'] / 1e3:.1f}"),
    ('measured/model', _vs('model_schedule')),
]
_ARRIVALS: list[Column] = [
    ('model kB, arrivals', lambda p, ph: (f"{ph['model']['wire_bytes'] / 1e3:.1f}"
                                          if ph.get('accept_times') else '-')),
    ('measured/model', lambda p, ph: _vs('model')(p, ph) if ph.get('accept_times') else '-'),
]

GRID_COLUMNS: list[Column] = [
    ('N', lambda p, ph: str(p['spec']['clients'])), ('M', lambda p, ph: str(p['spec']['goals'])),
    _GOALS, _CONFIG, *_STATUS, ('feedback share', _figure('feedback_share', '.0%')),
    ('held at go', _figure('held_at_go', 'd')), *_SCHEDULE, *_ARRIVALS,
    ('taken/client', _figure('status_taken_per_client', '.0f')),
    ('max entries', _figure('max_entries_wire', '.0f')),
    ('rx kB/client', _figure('rx_bytes_per_client', '.0f', 1e-3)),
    ('client CPU s', _figure('client_cpu_s_per_client', '.2f')),
]
TIMEOUT_COLUMNS: list[Column] = [
    ('result_timeout s', lambda p, ph: str(p['spec']['result_timeout_s'])), _CONFIG, _GOALS,
    *_STATUS, ('bytes/sample', _figure('wire_bytes_per_sample', '.0f')),
    ('entries/sample', _figure('entries_per_sample', '.1f')),
    ('max entries', _figure('max_entries_wire', '.0f')),
    ('largest kB', _figure('datagram_max', '.1f', 1e-3)), *_SCHEDULE,
    ('model max entries', lambda p, ph: str(ph['model']['max_entries'])),
    ('rx kB/client', _figure('rx_bytes_per_client', '.0f', 1e-3)),
    ('client CPU s', _figure('client_cpu_s_per_client', '.2f')),
]


def _table(columns: list[Column], rows: list[dict[str, Any]]) -> list[str]:
    """A Markdown table with a row per phase of ``rows`` (points); a failed point says so."""
    cells = []
    for point in rows:
        if point.get('error'):
            cells.append([f"{point['spec']['clients']} x {point['spec']['goals']}: failed: "
                          f"{point['error'][:80]}", *[''] * (len(columns) - 1)])
        cells += [[cell(point, phase) for _, cell in columns] for phase in point['phases']]
    return markdown_table([header for header, _ in columns], cells,
                          ['---' if header == 'configuration' else '---:'
                           for header, _ in columns]) + ['']


def markdown(all_points: list[dict[str, Any]]) -> str:
    """The grid and timeout tables, as Markdown."""
    grid = sorted((p for p in all_points if p['part'] == 'grid'),
                  key=lambda p: (p['spec']['goals'], p['spec']['clients']))
    timeouts = sorted((p for p in all_points if p['part'] == 'timeouts'),
                      key=lambda p: p['spec']['result_timeout_s'])
    out = _table(GRID_COLUMNS, grid) if grid else []
    if timeouts:
        out += _table(TIMEOUT_COLUMNS, timeouts)
    return '\n'.join(out)


def _measured(ax: Any, points: list[dict[str, Any]], x: Callable[[dict[str, Any]], float],
              config: str, style: str, colour: str, label: str) -> None:
    """Plot the captured status kB per client of ``config``'s phases of ``points`` against x."""
    pairs = [(x(p), ph['status']['status_bytes'] / 1e3)
             for p in points for ph in p['phases'] if ph['config'] == config]
    if pairs:
        ax.plot(*zip(*pairs), style, color=colour, ms=8, label=label)


def plot(all_points: list[dict[str, Any]], path: Path) -> Path:
    """Status bytes per client vs N for each M, and vs result_timeout; return the PNG's path."""
    from harness.plot import COLOURS, finish_axes, pyplot, save
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(17, 5))
    markers = {'rclpy': 'o', 'client': 'x', 'goals': '+', 'upstream': 's'}
    ylabel = 'status kB received per client (captured)'

    grid = [p for p in all_points if p['part'] == 'grid' and p['phases']]
    for k, m in enumerate(sorted({p['spec']['goals'] for p in grid})):
        row = sorted((p for p in grid if p['spec']['goals'] == m),
                     key=lambda p: p['spec']['clients'])
        axes[0].plot([p['spec']['clients'] for p in row],
                     [p['model']['wire_bytes'] / 1e3 for p in row], '--', color=f'C{k}', lw=1,
                     label=f'M={m}, model')
        for config, marker in markers.items():
            _measured(axes[0], row, lambda p: p['spec']['clients'], config, marker, f'C{k}',
                      f'M={m}, {load.CONFIG_LABELS[config]}')
    arrivals = [(p['spec']['clients'], ph['model']['wire_bytes'] / 1e3)
                for p in grid for ph in p['phases'] if ph.get('accept_times')]
    if arrivals:
        axes[0].plot(*zip(*arrivals), 'k_', ms=14, mew=2,
                     label="model, the server's measured arrivals")
    finish_axes(axes[0], 'client processes N (M goals each, sent at once; log)', ylabel,
                'status bytes per client vs N\n(result_timeout 2 s; dashed: model, goals at once)',
                xbase=2)

    timeouts = sorted((p for p in all_points if p['part'] == 'timeouts' and p['phases']),
                      key=lambda p: p['spec']['result_timeout_s'])
    if timeouts:
        spec = timeouts[0]['spec']
        ts = [p['spec']['result_timeout_s'] for p in timeouts]
        axes[1].plot(ts, [p['model']['wire_bytes'] / 1e3 for p in timeouts], 'k--', lw=1,
                     label='model')
        for config, marker in markers.items():
            _measured(axes[1], timeouts, lambda p: p['spec']['result_timeout_s'], config,
                      marker + '-', COLOURS[config], load.CONFIG_LABELS[config])
        finish_axes(axes[1], "server's result_timeout, s (log)", ylabel,
                    f"status bytes per client vs result_timeout\n({spec['clients']} clients, "
                    f"a goal each every {spec['goal_interval_s']:g} s for "
                    f"{spec['goals'] * spec['goal_interval_s']:.0f} s)")
        phases = [(p['spec']['result_timeout_s'], ph['status']) for p in timeouts
                  for ph in p['phases']]
        axes[2].plot([t for t, _ in phases], [s['wire_bytes_per_sample'] / 1e3 for _, s in phases],
                     'o-', label='mean status sample (wire bytes)')
        axes[2].plot([t for t, _ in phases], [s['datagram_max'] / 1e3 for _, s in phases], 's-',
                     label='largest status sample (UDP datagram)')
        finish_axes(axes[2], "server's result_timeout, s (log)", 'kB',
                    'status message size vs result_timeout')
    return save(fig, path)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Measure (or report results files); print the tables; draw the plot."""
    args = parse_args(argv)
    paths = args.report or [run(args)]
    all_points = [analyse(p) for path in paths for p in json.loads(path.read_text())['points']]
    print(markdown(all_points))
    print(f'plot: {plot(all_points, args.plot)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
