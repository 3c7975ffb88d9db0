# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The soak: one action server, eight client processes that keep coming and going, for minutes.

One Fibonacci action server publishes feedback every 10 ms (100 Hz) to each running goal
(:mod:`harness.server`, keep-last 1000 reliable queues). ``--clients`` (8) slots each
run client processes one after the other until the time is up. A client process:

1. creates its action client in the mode under test, waits for the server and completes one goal
   of order 0 (a round trip that proves the endpoints matched; it has no feedback), resent every
   2 s up to 10 times: a goal response written before the server matched the client is lost;
2. sends 1..``--max-goals`` goals of ``--orders`` feedback messages each, with feedback callbacks,
   and cancels each with probability ``--cancel`` at a random moment;
3. waits for every result, then until it has taken every feedback message the results say were
   published (at most ``STRAGGLER_S``, 15 s: a lost sample is resent after the server's next
   heartbeat), and half a second more for anything that should not arrive; reports; exits.

Modes: ``client`` and ``goals`` (:class:`cft_action.ActionClient`), ``rclpy`` (plain
:class:`rclpy.action.ActionClient`, the baseline, only when asked for) and ``upstream``
(:class:`harness.upstream.UpstreamEquivalentActionClient`, the Rolling algorithm: 16 ``%n``
parameters per goal, a goal added on acceptance and removed on its result, ``""`` after the last
goal, disabled for good past 6 goals). Each mode runs with the server guard ``on`` and ``off``.

Reported per configuration:

- **server crashes**: the server is watched every 0.5 s; a crashed server's signal and backtrace
  (from its core, read with gdb) are recorded and a new server is started, so a run goes on;
  client lives that overlapped a server outage are counted as *disrupted* and left out of the
  feedback accounting;
- **lost feedback**: for each goal, the server's result carries how many feedback messages it
  published for that goal; lost = published - distinct messages the client took from rcl;
- **foreign feedback**: messages the client took whose goal is not one of its own.

Feedback is counted where rclpy takes it from rcl (``take_data``), not in callbacks, so the three
modes are measured alike. Every process has one ROS domain per configuration, one that
no other process on the host uses (harness.domain), and localhost-only discovery; every wait is
bounded.

    python -m benchmarks.soak                         # 10 minutes per configuration, 6 of them
    python -m benchmarks.soak --minutes 2 --modes client goals --guard on
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import random
import shutil
import statistics
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from typing import Any, Optional

from harness.crash import (alive, core_backtrace, crash_site, machine_line, plain_env,
                           server_command, server_env, signal_name, stats_of)
from harness.domain import unused_domain
from harness.proc import Proc, main_or_role, python_module
from harness.report import say
from harness.server import feedback_reader_gids, queue_kwargs

MODES = ('client', 'goals', 'upstream')
DEPTH = 1000
#: Seconds a client waits, after its last result, for feedback still on the way (see role_client).
STRAGGLER_S = 15.0


# ==================================================================================================
# The client process
# ==================================================================================================

def role_client(action: str, mode: str, seed: int, max_goals: int, order_min: int,
                order_max: int, cancel_p: float, period: float) -> int:
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from test_msgs.action import Fibonacci
    from unique_identifier_msgs.msg import UUID

    from harness.client import recording_feedback

    rng = random.Random(seed)
    node = Node(f'soak_{uuid.uuid4().hex[:8]}')
    qos = queue_kwargs(str(DEPTH), 'sub')
    if mode == 'upstream':
        from harness.upstream import UpstreamEquivalentActionClient
        client = recording_feedback(UpstreamEquivalentActionClient)(node, Fibonacci, action, **qos)
    elif mode == 'rclpy':
        from rclpy.action import ActionClient as RclpyActionClient
        client = recording_feedback(RclpyActionClient)(node, Fibonacci, action, **qos)
    else:
        from cft_action import ActionClient
        client = recording_feedback(ActionClient)(node, Fibonacci, action, feedback_filter=mode,
                                                  **qos)
    client.feedback_taken = []
    executor = SingleThreadedExecutor()
    executor.add_node(node)

    def spin_until(predicate, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not predicate() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.02)
        return predicate()

    def new_uuid() -> UUID:
        if mode in ('upstream', 'rclpy'):
            return UUID(uuid=list(os.urandom(16)))
        return client.new_goal_uuid()

    t0 = time.monotonic()
    report: dict[str, Any] = {'mode': mode}
    if not client.wait_for_server(timeout_sec=20.0):
        say('RESULT', json.dumps({**report, 'failed': 'no server'}))
        return 0
    # A goal response written before the server's response writer matched this client is lost for
    # good (volatile), as with plain rclpy: the probe is resent every 2 s, up to 10 times, with a
    # new UUID each time (only the last probe is own; earlier ones have no feedback).
    probe_uuids = []
    for _ in range(10):
        probe_uuids.append(new_uuid())
        probe = client.send_goal_async(Fibonacci.Goal(order=0), goal_uuid=probe_uuids[-1])
        if spin_until(probe.done, 2.0):
            break
    report['probes'] = len(probe_uuids)
    # Named as in the measured runs: 'not accepted' is no goal response in time, or a rejection.
    if not probe.done() or not probe.result().accepted:
        why = 'rejected' if probe.done() else 'no goal response in 20 s'
        say('RESULT', json.dumps({**report, 'failed': f'probe goal not accepted ({why})'}))
        return 0
    # The result response can be lost the same way (the result service matches on its own).
    for _ in range(10):
        probe_result = probe.result().get_result_async()
        if spin_until(probe_result.done, 2.0):
            break
    if not probe_result.done():
        say('RESULT', json.dumps({**report, 'failed': 'probe result missing'}))
        return 0
    report['ready_s'] = round(time.monotonic() - t0, 2)

    goals = []  # [uuid bytes, order, send future, cancel at, result future, canceled]
    for _ in range(rng.randint(1, max_goals)):
        goal_uuid = new_uuid()
        order = rng.randint(order_min, order_max)
        cancel_at = (time.monotonic() + rng.uniform(0.05, order * period * 0.8)
                     if rng.random() < cancel_p else None)
        future = client.send_goal_async(Fibonacci.Goal(order=order),
                                        feedback_callback=lambda _m: None, goal_uuid=goal_uuid)
        goals.append([bytes(goal_uuid.uuid), order, future, cancel_at, None, False])
        executor.spin_once(timeout_sec=0)

    def step() -> bool:
        """Ask for results and cancel as due; True when every goal has its result."""
        now = time.monotonic()
        complete = True
        for goal in goals:
            _, _, future, cancel_at, result, canceled = goal
            if not future.done():
                complete = False
                continue
            handle = future.result()
            if not handle.accepted:
                continue
            if result is None:
                goal[4] = result = handle.get_result_async()
            if cancel_at is not None and not canceled and now >= cancel_at and not result.done():
                handle.cancel_goal_async()
                goal[5] = True
            complete &= result.done()
        return complete

    finished = spin_until(step, 30.0 + order_max * period * 3)

    def published_to(goal: list) -> int:
        """Feedback messages the server published for a goal, from its result (0 if none)."""
        future, result = goal[2], goal[4]
        if not future.done() or result is None or not result.done():
            return 0
        sequence = result.result().result.sequence
        return int(sequence[0]) if len(sequence) else 0

    expected = {goal[0]: published_to(goal) for goal in goals}

    def all_taken() -> bool:
        taken: dict[bytes, set[int]] = {}
        for goal_uuid, k in client.feedback_taken:
            taken.setdefault(goal_uuid, set()).add(k)
        return all(len(taken.get(u, ())) >= n for u, n in expected.items())

    # Stragglers: a sample lost on the way is resent after the server's next heartbeat (3 s), and
    # a reliable reader holds back what follows it until then. A client that left one second after
    # its last result counted those as lost (hundreds per 10 minutes on a loaded machine), which is
    # the harness leaving early, not the library losing them.
    t_linger = time.monotonic()
    spin_until(all_taken, STRAGGLER_S)
    report['linger_s'] = round(time.monotonic() - t_linger, 2)
    end = time.monotonic() + 0.5  # and anything that should not arrive
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)

    own = {bytes(u.uuid) for u in probe_uuids}
    own.update(goal[0] for goal in goals)
    received: dict[bytes, set[int]] = {}
    foreign = duplicates = 0
    for goal_uuid, k in client.feedback_taken:
        if goal_uuid not in own:
            foreign += 1
        elif k in received.setdefault(goal_uuid, set()):
            duplicates += 1
        else:
            received[goal_uuid].add(k)
    published = lost = lost_at_start = rejected = canceled = no_result = 0
    for goal_uuid, _order, future, _cancel_at, result, _asked in goals:
        if not future.done() or result is None or not result.done():
            no_result += 1
            continue
        if not future.result().accepted:
            rejected += 1
            continue
        count = expected[goal_uuid]
        canceled += result.result().status == 5  # GoalStatus.STATUS_CANCELED
        published += count
        got = {k for k in received.get(goal_uuid, set()) if 0 <= k < count}
        lost += count - len(got)
        # Lost before the first message that arrived: a filter that did not match the goal yet.
        lost_at_start += min(got) if got else count
    if mode == 'upstream':
        filter_sets = client.filter_sets
        filter_note = client.disabled_reason
    elif mode == 'rclpy':
        filter_sets, filter_note = 0, 'plain rclpy: no filter'
    else:
        state = client.feedback_filter_state
        filter_sets = (1 if state.active or state.updates else 0) + state.updates
        filter_note = state.reason
        # Where a lost message went: taken from rcl and dropped by the library (feedback_dropped),
        # or never taken; and whether the DDS reader judged samples itself (filtered_in).
        report.update({'library_taken': state.feedback_taken,
                       'library_dropped': state.feedback_dropped,
                       'filtered_in': state.filtered_in, 'held_goals': state.held_goals,
                       'arrival_timeouts': state.arrival_timeouts})
        if lost:  # to replay the filter's verdicts on the goals that lost feedback
            report['expression'] = state.expression
    if lost:  # to look it up among the readers that the server knew of when it took each goal
        report['goal_uuids'] = [goal[0].hex() for goal in goals]
        report['reader_gids'] = feedback_reader_gids(
            node, node.resolve_topic_name(action) + '/_action/feedback', node.get_name())
    report.update({
        'finished': finished, 'goals': len(goals), 'no_result': no_result,
        'rejected': rejected, 'canceled': canceled, 'published': published, 'lost': lost,
        'lost_at_start': lost_at_start,
        'foreign': foreign, 'duplicates': duplicates, 'taken': len(client.feedback_taken),
        'filter_sets': filter_sets, 'filter_note': filter_note,
        'life_s': round(time.monotonic() - t0, 2)})
    say('RESULT', json.dumps(report))
    client.destroy()
    node.destroy_node()
    return 0


#: The child processes of this script: ``soak.py _role client ARGS...``.
ROLES = {'client': role_client}


# ==================================================================================================
# The harness
# ==================================================================================================

class Soak:
    """One configuration: a mode, guard on or off, for ``minutes``."""

    def __init__(self, mode: str, guarded: bool, opts: argparse.Namespace) -> None:
        self.mode, self.guarded, self.opts = mode, guarded, opts
        self.domain = unused_domain()
        self.action = f'soak_{uuid.uuid4().hex[:10]}'
        self.lock = threading.Lock()
        self.lives: list[dict[str, Any]] = []
        self.crashes: list[dict[str, Any]] = []
        self.outages: list[tuple[float, float]] = []  # (last seen alive, replacement ready)
        self.server: Optional[Proc] = None
        self.server_dir = ''
        self.server_stats: list[dict[str, Any]] = []
        self.seed = random.randrange(2 ** 31)

    def start_server(self) -> bool:
        self.server_dir = tempfile.mkdtemp(prefix='cft_soak_')
        # Recording the readers at each take lets a lossy life be checked for a late match.
        self.server = Proc('server', server_command(self.action, self.opts.period, 0, DEPTH,
                                                    record_readers=True),
                           server_env(self.domain, self.guarded), cwd=self.server_dir, core=True)
        ready = self.server.wait_for('READY', 60.0) is not None
        say(f'    server pid {self.server.pid} (guard {"on" if self.guarded else "off"}, '
            f'domain {self.domain}): {"ready" if ready else "NOT READY"}')
        return ready

    def finish_server(self, at_stop: bool) -> dict[str, Any]:
        """Stop (or reap) the server; return its signal, stats and backtrace."""
        server = self.server
        assert server is not None
        was_alive = server.poll() is None
        if was_alive:
            server.send('stats')
            server.wait_for('STATS', 5.0, after=len(server.lines))
            self.note_readers_of_lost_goals(server)
        stats = [stats_of(line) for line in server.all('STATS')]
        stats = [s for s in stats if s]
        server.stop()
        rc = server.poll()
        info: dict[str, Any] = {'rc': rc, 'signal': signal_name(rc), 'alive_at_stop': was_alive}
        if stats:
            first, last = stats[0], stats[-1]
            info['published'] = last['published']
            info['feedback_per_s'] = round(last['published'] / max(1e-9, last['t'] - first['t']))
            info['late_ticks'] = last['late_ticks']
            info['guard_calls'] = last.get('guard_calls')
            info['cpu_s'] = round(last['cpu_s'], 1)
        if rc is not None and rc < 0:
            core, frames = core_backtrace(self.server_dir, server.pid, keep=self.opts.keep_cores)
            info.update(core=core, backtrace=frames)
            if core is None:
                info['backtrace_note'] = 'no core file'
        if not self.opts.keep_cores:
            shutil.rmtree(self.server_dir, ignore_errors=True)
        return info

    def note_readers_of_lost_goals(self, server: Proc) -> None:
        """For each life that lost feedback: whether the server's graph showed the life's reader
        when it took each goal (``reader_known_at_take``, by goal UUID), or None if not recorded."""
        with self.lock:
            lossy = [life for life in self.lives if life.get('reader_gids')]
        if not lossy:
            return
        after = len(server.lines)
        server.send('readers')
        line = server.wait_for('READERS', 10.0, after=after)
        readers = json.loads(line.split(' ', 1)[1]) if line else {}
        for life in lossy:
            own = set(life['reader_gids'])
            life['reader_known_at_take'] = {
                goal: (bool(own & set(readers[goal])) if goal in readers else None)
                for goal in life.get('goal_uuids', [])}

    def life(self, slot: int, n: int) -> None:
        o = self.opts
        seed = self.seed + slot * 100_000 + n
        start = time.monotonic()
        proc = Proc(f'client{slot}.{n}',
                    python_module('benchmarks.soak', '_role', 'client', self.action, self.mode,
                                  seed, o.max_goals, o.orders[0], o.orders[1], o.cancel,
                                  o.period), plain_env(self.domain))
        line = proc.wait_for('RESULT', 90.0 + STRAGGLER_S + o.orders[1] * o.period * 3)
        rc = proc.wait(15.0)
        if rc is None:
            rc = proc.stop()
        record: dict[str, Any] = {'slot': slot, 'start': start, 'end': time.monotonic(),
                                  'rc': rc}
        if line is None:
            record['failed'] = 'no result'
            record['tail'] = proc.tail(8)
        else:
            record.update(json.loads(line.split(' ', 1)[1]))
        if rc not in (0, None):  # a client process that crashed, with or without a result
            record['client_exit'] = signal_name(rc)
        with self.lock:
            self.lives.append(record)

    def slot_loop(self, slot: int, end: float) -> None:
        n = 0
        while time.monotonic() < end:
            try:
                self.life(slot, n)
            except Exception as e:  # noqa: BLE001 (a harness error must not end the soak)
                with self.lock:
                    self.lives.append({'slot': slot, 'failed': f'harness: {e!r}',
                                       'start': time.monotonic(), 'end': time.monotonic()})
            n += 1

    def run(self) -> dict[str, Any]:
        o = self.opts
        t0 = time.monotonic()
        if not self.start_server():
            info = self.finish_server(at_stop=True)
            return {'mode': self.mode, 'guard': self.guarded, 'error': 'server not ready',
                    'server': info}
        end = t0 + o.minutes * 60
        slots = [threading.Thread(target=self.slot_loop, args=(slot, end), daemon=True)
                 for slot in range(o.clients)]
        for thread in slots:
            thread.start()
            time.sleep(0.25)  # staggered starts
        last_alive = time.monotonic()
        next_progress = t0 + 60.0
        while time.monotonic() < end:
            time.sleep(0.5)
            if time.monotonic() >= next_progress:
                next_progress += 60.0
                self.progress(time.monotonic() - t0)
            assert self.server is not None
            if self.server.poll() is None and not self.server_dead_in_proc():
                last_alive = time.monotonic()
                continue
            self.server.wait(120.0)  # until its core is written
            crash = self.finish_server(at_stop=False)
            crash['at_s'] = round(last_alive - t0, 1)
            with self.lock:
                crash['lives_before'] = len(self.lives)
            self.crashes.append(crash)
            say(f'    server crashed at {crash["at_s"]} s ({crash["signal"]}): '
                f'{crash_site(crash)}')
            ok = self.start_server()
            self.outages.append((last_alive, time.monotonic()))
            if not ok:
                say('    replacement server not ready: ending this configuration')
                break
            last_alive = time.monotonic()
        for thread in slots:  # lives in flight end within their own bounds
            thread.join(120.0 + o.orders[1] * o.period * 3)
        final = self.finish_server(at_stop=True)
        return self.summarize(final, time.monotonic() - t0)

    def progress(self, elapsed: float) -> None:
        """One line a minute, so that a 10-minute configuration shows it is alive."""
        with self.lock:
            lives = list(self.lives)
        total = {key: sum(life.get(key, 0) for life in lives) for key in ('lost', 'foreign')}
        failed = sum('failed' in life for life in lives)
        say(f'    {elapsed / 60:.0f}/{self.opts.minutes:g} min: {len(lives)} client lives '
            f'({failed} failed), lost {total["lost"]}, foreign {total["foreign"]}, '
            f'server crashes {len(self.crashes)}')

    def server_dead_in_proc(self) -> bool:
        assert self.server is not None
        return not alive(self.server.pid)

    def disrupted(self, life: dict[str, Any]) -> bool:
        return any(life['start'] <= ready and life['end'] >= alive
                   for alive, ready in self.outages)

    def summarize(self, final: dict[str, Any], wall: float) -> dict[str, Any]:
        counted = [life for life in self.lives if not self.disrupted(life)]
        ok = [life for life in counted if 'failed' not in life]
        failed = [life for life in counted if 'failed' in life]
        reasons: dict[str, int] = {}
        for life in failed:
            reasons[life['failed']] = reasons.get(life['failed'], 0) + 1
        total = {key: sum(life.get(key, 0) for life in ok)
                 for key in ('goals', 'canceled', 'published', 'lost', 'lost_at_start',
                             'foreign', 'duplicates',
                             'no_result', 'filter_sets', 'taken')}
        client_exits = [life.get('client_exit') for life in self.lives if life.get('client_exit')]
        notes = sorted({life['filter_note'] for life in ok if life.get('filter_note')})
        return {
            'mode': self.mode, 'guard': self.guarded, 'minutes': self.opts.minutes,
            'domain': self.domain, 'wall_s': round(wall, 1),
            'lives': len(self.lives), 'lives_ok': len(ok),
            'lives_disrupted': len(self.lives) - len(counted), 'lives_failed': len(failed),
            'failure_reasons': reasons, 'client_exits': client_exits,
            'lives_with_lost': sum(1 for life in ok if life.get('lost')),
            'lives_with_foreign': sum(1 for life in ok if life.get('foreign')),
            'life_s_median': (statistics.median(life['life_s'] for life in ok) if ok else None),
            **total, 'filter_notes': notes[:5],
            'server_crashes': len(self.crashes), 'crashes': self.crashes, 'server_final': final,
            'failed_tails': [life.get('tail') for life in failed if life.get('tail')][:3],
            'life_records': [{k: v for k, v in life.items() if k != 'tail'}
                             for life in self.lives],
        }


def table(results: list[dict[str, Any]]) -> str:
    rows = ['| mode | guard | minutes | server crashes | client lives (ok / disrupted / failed) '
            '| goals (canceled) | feedback published to them | lost | foreign '
            '| filter sets by clients '
            '| discovery calls through the guard (reader info / reader removed) |',
            '|---|---|---|---|---|---|---|---|---|---|---|']
    for r in results:
        if 'error' in r:
            rows.append(f'| {r["mode"]} | {"on" if r["guard"] else "off"} | | '
                        f'{r["error"]} | | | | | | | |')
            continue
        calls = (r['server_final'].get('guard_calls') or {})
        events = (f'{calls.get("process_reader_filter_info", 0)} / '
                  f'{calls.get("remove_reader_filter", 0)}'
                  if calls and r['server_crashes'] == 0 else 'n/a (not guarded)'
                  if not r['guard'] else 'see crashes')
        lost = str(r['lost'])
        if r['lost']:
            lost += f' ({r["lost_at_start"]} at goal start)'
        crashes = str(r['server_crashes'])
        if r['crashes']:
            crashes += ' (at ' + ', '.join(f'{c["at_s"]:g} s {c["signal"]}'
                                           for c in r['crashes']) + ')'
        rows.append(
            f'| {r["mode"]} | {"on" if r["guard"] else "off"} | {r["minutes"]:g} | {crashes} | '
            f'{r["lives"]} ({r["lives_ok"]} / {r["lives_disrupted"]} / {r["lives_failed"]}) | '
            f'{r["goals"]} ({r["canceled"]}) | {r["published"]} | {lost} | {r["foreign"]} | '
            f'{r["filter_sets"]} | {events} |')
    return '\n'.join(rows)


def main(argv: list[str]) -> int:
    """Run the benchmark with the command line ``argv``."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=10.0, help='per configuration')
    parser.add_argument('--modes', nargs='+', choices=[*MODES, 'rclpy'], default=list(MODES),
                        help="'rclpy' (plain rclpy.action.ActionClient, the baseline) on request")
    parser.add_argument('--guard', nargs='+', choices=['on', 'off'], default=['on', 'off'])
    parser.add_argument('--runs', type=int, default=1, help='runs of each configuration')
    parser.add_argument('--clients', type=int, default=8, help='client processes at a time')
    parser.add_argument('--period', type=float, default=0.01, help='server feedback period, s')
    parser.add_argument('--max-goals', type=int, default=3, help='goals per client life, at most')
    parser.add_argument('--orders', type=int, nargs=2, default=[20, 80], metavar=('MIN', 'MAX'),
                        help='feedback messages per goal')
    parser.add_argument('--cancel', type=float, default=0.3,
                        help='probability that a goal is canceled')
    parser.add_argument('--keep-cores', action='store_true')
    parser.add_argument('--json', metavar='PATH', help='also write the results as JSON')
    opts = parser.parse_args(argv)
    header = {'date_utc': datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M'),
              'machine': machine_line(), 'command': 'python -m benchmarks.soak ' + ' '.join(argv)}
    print(json.dumps(header), flush=True)
    results = []
    configs = [(mode, g == 'on') for _ in range(opts.runs) for mode in opts.modes
               for g in opts.guard]
    for i, (mode, guarded) in enumerate(configs, 1):
        print(f'[{i}/{len(configs)}] mode={mode} guard={"on" if guarded else "off"} '
              f'{opts.minutes:g} min ...', flush=True)
        r = Soak(mode, guarded, opts).run()
        results.append(r)
        brief = {k: r.get(k) for k in ('lives', 'lives_ok', 'lives_disrupted', 'lives_failed',
                                       'failure_reasons', 'client_exits', 'goals', 'published',
                                       'lost', 'lost_at_start', 'foreign', 'duplicates',
                                       'filter_sets',
                                       'server_crashes', 'life_s_median', 'filter_notes')}
        brief['server'] = {k: r.get('server_final', {}).get(k)
                           for k in ('signal', 'feedback_per_s', 'guard_calls', 'cpu_s')}
        print('    ' + json.dumps(brief), flush=True)
        for tail in r.get('failed_tails', []):
            print('    ' + tail.replace('\n', '\n    '), flush=True)
        if opts.json:  # after every configuration, so that an interrupted soak keeps its results
            Path(opts.json).write_text(json.dumps({'header': header, 'results': results},
                                                  indent=1, default=str))
    print()
    print(table(results))
    return 0


if __name__ == '__main__':
    sys.exit(main_or_role(main, ROLES))
