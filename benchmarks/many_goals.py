# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""One client, many concurrent goals: does every feedback message arrive, and at what cost?

Usage: ``python -m benchmarks.many_goals [--goals 10000] [--order 4] [--period 2.0]
[--configs client,rclpy] [--depth N] [--server-executor single|multi] [--stall-s 90]
[--timeout 1800] [--profile S] [--out FILE] [--plot FILE]``, or ``--markdown JSON...`` to print
the tables of saved results again.

Issue 14, item 4. For each configuration in turn (``client``: :class:`cft_action.ActionClient` in
its default mode; ``rclpy``: plain :class:`rclpy.action.ActionClient`), and each goal count of
``--goals`` (a comma-separated list runs a series), the benchmark starts a fresh server
(``cft-action guard -- python -m harness.server ... --hold-goals GOALS``) and one client process
(:mod:`harness.client`), and the client sends GOALS goals of ORDER feedback messages each, without
waiting between them. The server publishes each goal's first feedback in the first line of
``execute``, then holds every goal until all GOALS have been accepted (so that they are all live at
once), then publishes the others one per ``--period`` per goal, and ends the goals.

Queues: rclpy's default goal service depth is 10, so every queue of both sides (goal, result and
cancel services, feedback) is keep-last ``--depth``, reliable, as a user who sends that many goals
at once must set it: by default GOALS x ORDER + 100 (all the run's feedback), at least 1000. The
status topic keeps rclpy's default (keep-last 1, transient local): each status message lists every
goal the server holds, so only the latest matters.

Per phase it records: feedback callbacks per goal against the feedback the server published per goal
(``GOALS`` of both sides), foreign feedback taken (goals not this client's), the client's and the
server's CPU (``getrusage`` user + system, from ``go`` to the end) and peak RSS (``ru_maxrss``; also
RSS and CPU sampled from ``/proc`` every 0.5 s, for the plot), the filter's updates
(``feedback_filter_state.updates``) and the server guard's count of filter events at its writer
(``process_reader_filter_info`` calls), and the times: all goals sent, last goal response, all goals
accepted at the server, all goals done, last feedback callback. A phase that stops making progress
for ``--stall-s`` seconds gets the threads of both processes from gdb, then the server is told to
release the goals it holds, and the phase is accounted as far as it got. With ``--profile S`` and
py-spy installed, both processes are sampled for S seconds (Python and native frames; py-spy
stops a process briefly for each of 50 samples a second, and the times include it) once half the
goals were accepted, and once the goals were released: where the time goes.

Every process has ``ROS_DOMAIN_ID`` ``--domain`` (103) and localhost-only discovery; every wait is
bounded and every process is stopped. Results go to
``benchmarks/results/many-goals-<date>-<host>.json`` with a markdown table and a plot.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import threading
import time
from pathlib import Path
from typing import Any, Optional, Sequence

from harness import load
from harness.crash import live_backtrace, machine_line, plain_env
from harness.machine import environment_facts
from harness.procstat import Sampler, profile
from harness.proc import Proc, ROOT, guard_command, python_module
from harness.report import fmt, markdown_table, say

#: Labels of the configurations, in the order of the table's columns.
LABELS = {'client': 'cft_action (client mode)', 'rclpy': 'plain rclpy'}

#: Seconds between polls of the server's counters while the goals run.
POLL_S = 1.0

#: Frames whose share of the profile's samples the profile table shows (substrings of py-spy's
#: frames): where the work that grows with the number of live goals goes.
WATCH = {
    'goal_status_array__convert_to_py': 'GoalStatusArray converted to Python (take_status)',
    'Future._set_executor': "every future of the waitable, at each wake (_take_waitable)",
    'rclpy/executors.py:58': 'executor scans its tasks, every spin (executors.py:580-589)',
    'rcl_action_get_goal_status_array': 'status array built (publish_status)',
    'rcl_action_publish_status': 'status array published',
    'rcl_action_server_goal_exists': 'goal id looked up among all goals',
    'publish_feedback': 'feedback published',
    'rcl_wait': 'waiting (rcl_wait)',
}


def status_message_bytes(goals: int) -> int:
    """Serialized size (CDR) of a GoalStatusArray that lists ``goals`` goals: one status message."""
    from action_msgs.msg import GoalStatus, GoalStatusArray
    from rclpy.serialization import serialize_message
    message = GoalStatusArray(status_list=[GoalStatus() for _ in range(goals)])
    return len(serialize_message(message))


def queue_depth(goals: int, order: int) -> int:
    """The default ``--depth``: room for all the run's feedback (:func:`load.queue_depth`)."""
    return load.queue_depth(load.LoadSpec(clients=1, goals=goals, order=order))


class Phase:
    """One configuration and goal count: a fresh guarded server and one client process."""

    def __init__(self, config: str, goals: int, opts: argparse.Namespace) -> None:
        self.config = config
        self.goals = goals
        self.opts = opts
        self.depth = opts.depth or queue_depth(goals, opts.order)
        self.action = f'/many_goals_{os.urandom(4).hex()}'
        self.env = plain_env(opts.domain)
        self.notes: list[str] = []
        self.backtraces: dict[str, Optional[str]] = {}
        self.profiles: dict[str, Any] = {}

    def run(self) -> dict[str, Any]:
        """Run the phase and return its raw figures; the processes are stopped however it ends."""
        opts = self.opts
        label = f'[{self.config} x {self.goals}]'
        server_argv = guard_command() + python_module(
            'harness.server', self.action, opts.period, '--depth', self.depth,
            '--hold-goals', self.goals, '--executor', opts.server_executor)
        server = Proc('server', server_argv, self.env)
        client: Optional[Proc] = None
        sampler: Optional[Sampler] = None
        try:
            guard_line = server.expect('STATUS', 60)
            server.expect('READY', 60)
            client = Proc(f'{self.config} client', python_module(
                'harness.client', self.action, self.config, self.goals, opts.order, self.depth),
                self.env)
            client.expect('READY', 120)
            before = server.request_json('stats', 'STATS')
            ready = client.request_json('report', 'RESULT')
            sampler = Sampler({'server': server.pid, 'client': client.pid})
            say(f'{label} client ready (probe goal done); server {guard_line}; depth {self.depth};'
                f' sending {self.goals} goals of {opts.order} feedback')
            go = time.monotonic()
            client.send('go')
            times = self._wait_for_goals(server, client, before, go, label)
            say(f'{label} goals done at {times["done_s"]:.1f} s; waiting for the client to take '
                'the rest')
            load.wait_for_quiet([client], time.monotonic(), 3.0, opts.timeout, say)
            times['window_s'] = time.monotonic() - go
            after = server.request_json('stats', 'STATS', 60)
            report = client.request_json('report', 'RESULT', 120)
            delivered = client.request_json('goals', 'GOALS', 120)
            published = server.request_json('goals', 'GOALS', 120)
            sampler.stop()
        finally:
            if sampler is not None:
                sampler.stop()
            if client is not None:
                client.stop()
            server.stop()
        if server.popen.returncode not in (0, None):
            self.notes.append(f'server exit status {server.popen.returncode}')
        return {
            'config': self.config, 'goals': self.goals, 'order': opts.order,
            'period_s': opts.period, 'depth': self.depth, 'action': self.action,
            'guard': guard_line, 'times': times, 'before': before, 'after': after,
            'ready': _without_latency(ready), 'report': report,
            'delivery': delivery(delivered, published, opts.order),
            'client_cpu_lifetime_s': client.cpu_lifetime_s if client else None,
            'server_cpu_lifetime_s': server.cpu_lifetime_s,
            'samples': {name: [(round(t, 2), rss, cpu) for t, rss, cpu in sampler.series(name)]
                        for name in ('server', 'client')}
            if sampler else {},
            'notes': self.notes, 'backtraces': self.backtraces, 'profiles': self.profiles,
        }

    def _wait_for_goals(self, server: Proc, client: Proc, base: dict[str, Any], go: float,
                        label: str) -> dict[str, Any]:
        """Poll the server until every goal was accepted, released and done; return the times.

        No progress (goals accepted, feedback published, goals done) for ``--stall-s`` seconds is
        a stall: the threads of both processes are read with gdb, and the server is told to release
        the goals it holds, so that the phase ends with what was accepted.
        """
        opts = self.opts
        times: dict[str, Any] = {'accepted_s': None, 'done_s': None, 'stalled_at': None,
                                 'timeline': []}
        last_progress, progress_at, shown = None, time.monotonic(), 0.0
        while True:
            stats = server.request_json('stats', 'STATS', 60)
            now = time.monotonic()
            held = stats['held_accepted'] - base['held_accepted']
            # (s since go, goals accepted, feedback published, goals active, server CPU s)
            times['timeline'].append((round(now - go, 2), held,
                                      stats['published'] - base['published'], stats['active'],
                                      round(stats['cpu_s'] - base['cpu_s'], 2)))
            if times['accepted_s'] is None and held >= self.goals:
                times['accepted_s'] = now - go
            released = stats['released'] is not None
            if opts.profile > 0:
                if held >= self.goals // 2 and 'accepting' not in self.profiles:
                    self._profile('accepting', now - go, held, server, client, label)
                if released and 'released' not in self.profiles:
                    self._profile('released', now - go, held, server, client, label)
            if released and stats['active'] == 0 and held > 0:
                times['done_s'] = now - go
                return times
            moving = (held, stats['published'], stats['active'])
            if moving != last_progress:
                last_progress, progress_at = moving, now
            if now - shown >= 5:
                shown = now
                say(f'{label} {now - go:6.1f} s: {held}/{self.goals} accepted, '
                    f'{stats["published"] - base["published"]} feedback published, '
                    f'{stats["active"]} active (peak {stats["peak_active"]}), server '
                    f'{stats["cpu_s"] - base["cpu_s"]:.1f} CPU s, '
                    f'{stats["maxrss_kb"] / 1024:.0f} MB')
            stalled = now - progress_at >= opts.stall_s
            if (stalled or now - go > opts.timeout) and times['stalled_at'] is None:
                why = (f'no progress for {opts.stall_s:g} s' if stalled
                       else f'not done within {opts.timeout:g} s')
                times['stalled_at'] = {'s': now - go, 'accepted': held, 'why': why}
                self.notes.append(f'{why} at {held}/{self.goals} accepted')
                say(f'{label} {why} at {held}/{self.goals} goals accepted: reading the threads')
                self.backtraces = {name: live_backtrace(proc.pid) for name, proc in
                                   (('server', server), ('client', client))}
                server.send('release')
                progress_at = time.monotonic()
            elif times['stalled_at'] is not None and (
                    now - progress_at >= opts.stall_s or now - go > 2 * opts.timeout):
                self.notes.append('still no progress after the release: given up')
                times['done_s'] = now - go
                return times
            time.sleep(POLL_S)


    def _profile(self, moment: str, at: float, held: int, server: Proc, client: Proc,
                 label: str) -> None:
        """Sample both processes at once for ``--profile`` seconds (py-spy)."""
        say(f'{label} profiling both processes for {self.opts.profile:g} s ({moment})')
        found: dict[str, Any] = {'at_s': at, 'accepted': held}

        def one(name: str, pid: int) -> None:
            found[name] = profile(pid, self.opts.profile, watch=list(WATCH))

        threads = [threading.Thread(target=one, args=(name, proc.pid))
                   for name, proc in (('server', server), ('client', client))]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(self.opts.profile + 90)
        self.profiles[moment] = found


def _without_latency(report: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in report.items() if k != 'latency_us'}


def delivery(delivered: dict[str, int], published: dict[str, int], order: int) -> dict[str, Any]:
    """Per goal, feedback callbacks against feedback published: complete, short, in excess.

    ``delivered`` has every goal the client sent (0 when nothing came); ``published`` every goal
    the server published feedback for.
    """
    short = {k: (published.get(k, 0), n) for k, n in delivered.items() if n < published.get(k, 0)}
    excess = {k: (published.get(k, 0), n) for k, n in delivered.items() if n > published.get(k, 0)}
    unknown = [k for k in published if k not in delivered]
    return {
        'goals_sent': len(delivered),
        'goals_with_feedback_published': sum(1 for k in delivered if published.get(k, 0) > 0),
        'goals_with_all_published': sum(1 for k in delivered if published.get(k, 0) == order),
        'published': sum(published.get(k, 0) for k in delivered),
        'delivered': sum(delivered.values()),
        'goals_complete': sum(1 for k, n in delivered.items() if n == published.get(k, 0) > 0),
        'goals_short': len(short), 'missing': sum(p - n for p, n in short.values()),
        'goals_in_excess': len(excess), 'excess': sum(n - p for p, n in excess.values()),
        'short_examples': dict(list(short.items())[:20]),
        'published_for_other_goals': sum(published[k] for k in unknown),
    }


def summarize(phase: dict[str, Any]) -> dict[str, Any]:
    """The figures of the table, from one phase's raw figures."""
    before, after, report, times = phase['before'], phase['after'], phase['report'], phase['times']
    d = phase['delivery']
    calls_before = before.get('guard_calls', {}).get('process_reader_filter_info', 0)
    calls_after = after.get('guard_calls', {}).get('process_reader_filter_info', 0)
    # The client's reader has the library's class (CFT_ACTION_UUID): the guard keeps it in its own
    # table and judges each sample in is_relevant (guard.filter_counts: kept, relevance_verdicts).
    compiled_before = before.get('guard_filter', {}).get('kept', 0)
    compiled = after.get('guard_filter', {}).get('kept', 0)
    latency = report.get('latency_us', [])
    return {
        'config': phase['config'], 'goals': phase['goals'],
        'accepted': report['accepted'], 'rejected': report['rejected'],
        'peak_active': after['peak_active'],
        'published': d['published'], 'delivered': d['delivered'],
        'goals_complete': d['goals_complete'], 'goals_short': d['goals_short'],
        'missing': d['missing'], 'excess': d['excess'],
        'foreign': report['foreign'], 'misrouted': report['misrouted'],
        'lib_dropped': report.get('lib_dropped'),
        'updates': report.get('updates_total', report.get('updates', 0)),
        # Fast DDS calls process_reader_filter_info for every reader a writer matches or sees
        # change, filtered or not; a filter update is one such call, and one filter compiled.
        'guard_filter_events_window': calls_after - calls_before,
        'guard_filter_events_total': calls_after,
        'guard_compiled_window': compiled - compiled_before, 'guard_compiled_total': compiled,
        # The feedback readers' verdicts: the status readers' are counted apart too.
        'guard_uuid_verdicts': sum(sign * (s.get('guard_filter', {}).get('relevance_verdicts', 0)
                                           - s.get('guard_status', {}).get('verdicts', 0))
                                   for sign, s in ((1, after), (-1, before))),
        'client_cpu_s': report['cpu_s'], 'client_maxrss_mb': report['maxrss_kb'] / 1024,
        'client_rss_ready_mb': phase['ready']['rss_kb'] / 1024,
        'client_rss_end_mb': report['rss_kb'] / 1024,
        'server_cpu_s': after['cpu_s'] - before['cpu_s'],
        'server_maxrss_mb': after['maxrss_kb'] / 1024,
        'server_rss_ready_mb': _first_rss_mb(phase, 'server'),
        'send_s': report['send_s'], 'last_response_s': report['last_response_s'],
        'accepted_s': times['accepted_s'], 'done_s': times['done_s'],
        'last_callback_s': report['last_callback_s'], 'window_s': times.get('window_s'),
        'stalled': times['stalled_at'],
        'late_ticks': after['late_ticks'] - before['late_ticks'],
        'latency_p50_ms': _ms(load.percentile(latency, 0.5)),
        'latency_p99_ms': _ms(load.percentile(latency, 0.99)),
        'latency_max_ms': _ms(max(latency, default=None)),
        'goal_response_errors': after['goal_response_errors'] - before['goal_response_errors'],
        'status_message_bytes': status_message_bytes(phase['goals']),
    }


def _ms(us: Optional[float]) -> Optional[float]:
    return None if us is None else us / 1000.0


def _first_rss_mb(phase: dict[str, Any], name: str) -> Optional[float]:
    series = [rss for _, rss, _ in phase['samples'].get(name, []) if rss]
    return series[0] / 1024 if series else None


#: Rows of the markdown table: (label, summary key, format); ratios are cft / plain.
ROWS: tuple[tuple[str, str, str], ...] = (
    ('goals accepted', 'accepted', 'd'), ('peak goals live at the server', 'peak_active', 'd'),
    ('feedback published for its goals', 'published', 'd'),
    ('feedback delivered to callbacks', 'delivered', 'd'),
    ('goals with every message delivered', 'goals_complete', 'd'),
    ('goals missing feedback / messages missing', 'short', ''),
    ('foreign feedback taken', 'foreign', 'd'),
    ('filter updates (`feedback_filter_state.updates`)', 'updates', 'd'),
    ('reader-filter calls at the server (process_reader_filter_info), run / total', 'events',
     ''),
    ('readers of the library\'s class the server guard keeps, run / total', 'compiled', ''),
    ('verdicts the guard gave for them (is_relevant)', 'guard_uuid_verdicts', 'd'),
    ('client CPU s (user+sys, go to end)', 'client_cpu_s', '.1f'),
    ('client peak RSS MB (ru_maxrss)', 'client_maxrss_mb', '.0f'),
    ('client RSS MB before go', 'client_rss_ready_mb', '.0f'),
    ('server CPU s (user+sys, go to end)', 'server_cpu_s', '.1f'),
    ('server peak RSS MB (ru_maxrss)', 'server_maxrss_mb', '.0f'),
    ('all goals sent, s', 'send_s', '.1f'), ('last goal response, s', 'last_response_s', '.1f'),
    ('all goals accepted (server), s', 'accepted_s', '.1f'),
    ('all goals done (server), s', 'done_s', '.1f'),
    ('last feedback callback, s', 'last_callback_s', '.1f'),
    ('feedback latency p50 / p99 ms', 'latency', ''),
    ('load average (1 min) before / after', 'load', ''),
)

#: Rows that get a ratio cft / plain.
RATIO_KEYS = {'delivered', 'client_cpu_s', 'client_maxrss_mb', 'server_cpu_s',
              'server_maxrss_mb', 'last_response_s', 'done_s', 'last_callback_s'}


def _cell(s: dict[str, Any], key: str, spec: str) -> str:
    if key == 'short':
        return f'{s["goals_short"]} / {s["missing"]}'
    if key == 'events':
        return f'{s["guard_filter_events_window"]} / {s["guard_filter_events_total"]}'
    if key == 'compiled':
        return f'{s["guard_compiled_window"]} / {s["guard_compiled_total"]}'
    if key == 'load':
        return f'{s["load_before"]:.2f} / {s["load_after"]:.2f}' if 'load_before' in s else '-'
    if key == 'latency':
        return f'{fmt(s["latency_p50_ms"], ".0f")} / {fmt(s["latency_p99_ms"], ".0f")}'
    return fmt(s.get(key), spec)


def summary_tables(summaries: Sequence[dict[str, Any]]) -> str:
    """One table per goal count: a column per configuration, and cft / plain where both ran."""
    out = []
    for goals in sorted({s['goals'] for s in summaries}):
        cols = [s for s in summaries if s['goals'] == goals]
        by_config = {s['config']: s for s in cols}
        ratio = 'client' in by_config and 'rclpy' in by_config
        head = ['', *(LABELS.get(s['config'], s['config']) for s in cols)]
        if ratio:
            head.append('cft / plain')
        rows = []
        for label, key, spec in ROWS:
            row = [label, *(_cell(s, key, spec) for s in cols)]
            if ratio:
                a, b = by_config['client'].get(key), by_config['rclpy'].get(key)
                row.append(f'{a / b:.2f}x' if key in RATIO_KEYS and a is not None and b else '')
            rows.append(row)
        out.append('\n'.join([f'**{goals} goals** (status message '
                              f'{cols[0]["status_message_bytes"]:,} B)', '',
                              *markdown_table(head, rows)]))
    return '\n\n'.join(out)


def profile_table(phases: Sequence[dict[str, Any]]) -> str:
    """Shares of the py-spy samples in :data:`WATCH`'s frames, per process, phase and moment."""
    columns = []
    for phase in phases:
        for moment, found in phase.get('profiles', {}).items():
            for name in ('client', 'server'):
                if found.get(name):
                    columns.append((f'{name}, {phase["config"]} x {phase["goals"]}, {moment} '
                                    f'({found["accepted"]} accepted)', found[name]))
    if not columns:
        return ''
    rows = [[label, *(f'{found["watched"].get(needle, 0):.0%}' for _, found in columns)]
            for needle, label in WATCH.items()]
    return '\n'.join(markdown_table(['share of samples', *(c for c, _ in columns)], rows))


def plot(phases: Sequence[dict[str, Any]], path: Path) -> Optional[Path]:
    """RSS and CPU of both processes, and goals accepted, over time: the largest goal count."""
    from harness.plot import pyplot
    try:
        plt = pyplot()
    except ImportError:
        return None
    largest = max(p['goals'] for p in phases)
    shown = [p for p in phases if p['goals'] == largest]
    fig, (rss_ax, cpu_ax, goals_ax) = plt.subplots(1, 3, figsize=(16, 4.5))
    styles = {'client': '-', 'rclpy': '--'}
    for phase in shown:
        timeline = phase['times'].get('timeline') or []
        if timeline:
            goals_ax.plot([row[0] for row in timeline], [row[1] for row in timeline],
                          styles.get(phase['config'], ':'), color='tab:green',
                          label=LABELS.get(phase['config'], phase['config']))
        for name, colour in (('client', 'tab:blue'), ('server', 'tab:orange')):
            series = [(t, rss, cpu) for t, rss, cpu in phase['samples'].get(name, [])
                      if rss is not None and cpu is not None]
            if not series:
                continue
            t0 = series[0][2]
            label = f'{name}, {LABELS.get(phase["config"], phase["config"])}'
            rss_ax.plot([t for t, _, _ in series], [rss / 1024 for _, rss, _ in series],
                        styles.get(phase['config'], ':'), color=colour, label=label)
            cpu_ax.plot([t for t, _, _ in series], [cpu - t0 for _, _, cpu in series],
                        styles.get(phase['config'], ':'), color=colour, label=label)
    rss_ax.set(title=f'RSS, {largest} goals', xlabel='s since sampling started', ylabel='MB')
    cpu_ax.set(title='CPU (user + system)', xlabel='s since sampling started', ylabel='CPU s')
    goals_ax.set(title='goals accepted by the server', xlabel='s since go', ylabel='goals')
    for ax in (rss_ax, cpu_ax, goals_ax):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--goals', default='10000',
                        help='goals the client sends at once; a comma-separated list runs a series')
    parser.add_argument('--order', type=int, default=4, help='feedback messages per goal')
    parser.add_argument('--period', type=float, default=2.0,
                        help='seconds between a goal\'s feedback messages after the hold')
    parser.add_argument('--configs', default='client,rclpy')
    parser.add_argument('--depth', type=int, default=0,
                        help='every queue\'s depth, both sides (default: goals x order + 100)')
    parser.add_argument('--server-executor', choices=('single', 'multi'), default='single')
    parser.add_argument('--stall-s', type=float, default=90.0,
                        help='seconds without progress that count as a stall')
    parser.add_argument('--timeout', type=float, default=1800.0,
                        help='seconds a phase\'s goals may take, and its drain')
    parser.add_argument('--profile', type=float, default=0.0,
                        help='seconds of py-spy sampling of both processes at half acceptance and '
                             'at the release (0: none)')
    parser.add_argument('--domain', type=int, default=103)
    parser.add_argument('--out', type=Path)
    parser.add_argument('--plot', type=Path)
    parser.add_argument('--markdown', type=Path, nargs='+',
                        help='print the tables of these result files (and with --plot, draw '
                             'the plot again); run nothing')
    return parser.parse_args(argv)


def write_result(out: Path, now: datetime.datetime, opts: argparse.Namespace,
                 argv: Optional[Sequence[str]], load_averages: dict[str, Any],
                 summaries: list[dict[str, Any]], phases: list[dict[str, Any]],
                 complete: bool) -> None:
    """Write the result file: machine, date, command, load averages, tables and raw phases."""
    result = {
        'date': now.isoformat(), 'host': platform.node(), 'machine': environment_facts(),
        'command': ' '.join([os.path.basename(sys.executable), '-m', 'benchmarks.many_goals',
                             *(argv if argv is not None else sys.argv[1:])]),
        'args': {k: str(v) if isinstance(v, Path) else v for k, v in vars(opts).items()},
        'complete': complete, 'load_average': load_averages, 'summaries': summaries,
        'table': summary_tables(summaries), 'profile_table': profile_table(phases),
        'phases': phases,
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run every goal count and configuration; write the JSON, the table and the plot."""
    opts = parse_args(argv)
    if opts.markdown:
        for path in opts.markdown:
            saved = json.loads(path.read_text())
            say(f'{path}: {saved["command"]} ({saved["date"]}, load average '
                f'{saved["load_average"]["start"][0]:.2f} at start)\n')
            say(summary_tables(saved['summaries']))
            if saved.get('profile_table'):
                say('\n' + saved['profile_table'])
            if opts.plot:
                say(f'plot: {plot(saved["phases"], opts.plot)}')
        return 0
    counts = [int(n) for n in opts.goals.split(',')]
    configs = opts.configs.split(',')
    now = datetime.datetime.now(datetime.timezone.utc)
    stem = f'many-goals-{now:%Y-%m-%d}-{platform.node()}'
    out = opts.out or ROOT / 'benchmarks' / 'results' / f'{stem}.json'
    figure = opts.plot or out.with_suffix('.png')
    say(machine_line())
    phases, summaries = [], []
    load_averages = {'start': os.getloadavg()}
    for goals in counts:
        for config in configs:
            load_before = os.getloadavg()
            phase = Phase(config, goals, opts).run()
            phase['load_average_before'] = load_before
            phase['load_average_after'] = os.getloadavg()
            phases.append(phase)
            summaries.append({**summarize(phase), 'load_before': load_before[0],
                              'load_after': phase['load_average_after'][0]})
            phase['report'] = _without_latency(phase['report'])  # the summary has percentiles
            # After every phase, so that a run cut short keeps the phases it finished.
            write_result(out, now, opts, argv, load_averages, summaries, phases, complete=False)
            s = summaries[-1]
            say(f'[{config} x {goals}] delivered {s["delivered"]}/{s["published"]}, '
                f'{s["goals_complete"]}/{goals} goals complete, foreign {s["foreign"]}, '
                f'updates {s["updates"]}, client {s["client_cpu_s"]:.1f} CPU s '
                f'{s["client_maxrss_mb"]:.0f} MB, server {s["server_cpu_s"]:.1f} CPU s '
                f'{s["server_maxrss_mb"]:.0f} MB; load {os.getloadavg()[0]:.2f}')
    load_averages['end'] = os.getloadavg()
    table = summary_tables(summaries)
    profiles = profile_table(phases)
    say('\n' + table + ('\n\n' + profiles if profiles else ''))
    write_result(out, now, opts, argv, load_averages, summaries, phases, complete=True)
    drawn = plot(phases, figure)
    say(f'\nresults: {out}' + (f'\nplot: {drawn}' if drawn else ''))
    return 0


if __name__ == '__main__':
    sys.exit(main())
