# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The differential soak: one seeded workload, against plain rclpy and each cft mode, goal by goal.

One action server runs for the whole benchmark, under ``cft-action guard --``: ``harness.server
--executor multi``, an rclpy ``ActionServer`` on a ``MultiThreadedExecutor`` that publishes each
goal's feedback ``k = 0`` in the first line of ``execute`` and ``k = 1..`` every ``--period``, and
counts what it published per goal UUID. The configurations (``--configs``, names
as in ``harness/client.py``: ``rclpy``, ``client``, ``goals``) run one after the other against it.

The workload. ``--slots`` client slots each start client processes one after the other. Life ``n``
of slot ``s`` is drawn from ``random.Random(f'{seed}/{s}/{n}')`` alone, so the same life gets the
same draws in every configuration:

- a ``MultiThreadedExecutor`` or a ``SingleThreadedExecutor``, and one action client or two in the
  process (on one node, sharing the executor);
- per client, 1..``--max-goals`` goals of ``--orders`` feedback messages, each sent at a drawn
  offset (a burst at 0 s, or staggered over a second); each goal with or without a feedback
  callback, with or without a caller-supplied ``goal_uuid`` (a random uuid4: no client-mode tag),
  and canceled at a drawn moment or not.

Plain rclpy runs first, for ``--duration`` seconds; each cft configuration then runs exactly the
lives that plain completed in each slot (bounded at twice the duration), so that every goal has a
counterpart in plain rclpy. A client process proves its endpoints with an order-0 goal
(``harness.client.probe``), then drives its goals from a timer on its executor (the node's
callback group, as the action clients: rclpy 7.1's ``send_goal_async`` is not safe against an
executor taking the response in another thread), asks for every result as rclpy users do, and
waits after the last result for feedback still on the way (``--linger``).

Per goal it compares the feedback numbers ``k`` delivered to the callback with plain rclpy's for
the same seeded goal, and reports:

- **fewer than plain**: goals where a cft mode delivered fewer ``k`` than plain did (and which
  ``k``). Those that lack ``k = 0`` and were sent within 2 s after a filter update of their
  client (``goals`` mode, or a caller-supplied untagged UUID in ``client`` mode) are counted apart
  as *first-message losses after a filter update*: the goal request overtook the filter update
  at the server, whose writer applied the old filter to the goal's first sample;
- **foreign**: callbacks given a message of another goal, and, in the cft modes, feedback taken
  from rcl for a goal that is not one of the client's own goals with a callback (another
  client's, or its own goal without a callback). Plain rclpy takes all feedback by design; its
  count is given as the baseline;
- **lost vs published**: for each goal with a callback, the server's count of published messages
  minus the distinct ``k`` delivered. Plain rclpy loses some too (a keep-last 10 queue that
  overflows on a busy machine; feedback arriving after the result, whose callback rclpy drops);
- **server crashes**: the server is watched; a crashed one is recorded and replaced, and the
  lives that overlapped the outage are left out of the comparison.

Every process has ``ROS_DOMAIN_ID`` ``--domain`` (88) and localhost-only discovery; every wait is
bounded, and every process started is stopped.

    python -m benchmarks.differential --duration 60 --markdown
    python -m benchmarks.differential --duration 200 --out benchmarks/results/differential-1.json
"""

from __future__ import annotations

import argparse
import datetime
import json
import random
import shutil
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from typing import Any, Optional

from harness.crash import core_backtrace, machine_line, plain_env, signal_name
from harness.machine import environment_facts
from harness.proc import Proc, guard_command, main_or_role, python_module
from harness.report import fmt, grid, say

CONFIGS = ('rclpy', 'client', 'goals')
#: Seconds a client may take to prove its endpoints (``probe``), per action client.
PROBE_S = 30.0
#: Seconds a goal may wait for its goal response.
RESPONSE_S = 15.0
#: A first-message loss counts as "after a filter update" when its goal was sent this soon after.
UPDATE_WINDOW_S = 2.0
#: Seconds between progress lines.
PROGRESS_S = 10.0


# ==================================================================================================
# The workload
# ==================================================================================================

def life_spec(seed: int, slot: int, n: int, opts: argparse.Namespace) -> dict[str, Any]:
    """Life ``n`` of ``slot``: its executor, its clients and their goals, from the seed alone."""
    rng = random.Random(f'{seed}/{slot}/{n}')
    spec: dict[str, Any] = {'executor': 'multi' if rng.random() < 0.5 else 'single',
                            'clients': 2 if rng.random() < opts.two_clients else 1, 'goals': []}
    for client in range(spec['clients']):
        staggered = rng.random() < 0.5
        for goal in range(rng.randint(1, opts.max_goals)):
            order = rng.randint(*opts.orders)
            cancel = (round(rng.uniform(0.02, order * opts.period * 0.8), 3)
                      if rng.random() < opts.cancel else None)
            spec['goals'].append({
                'client': client, 'goal': goal, 'order': order,
                'at': round(rng.uniform(0.0, 1.0), 3) if staggered else 0.0,
                'cb': rng.random() < opts.callback, 'caller': rng.random() < opts.caller,
                'cancel': cancel})
    return spec


# ==================================================================================================
# The client process: one life
# ==================================================================================================

def filter_updates(client: Any) -> int:
    state = getattr(client, 'feedback_filter_state', None)
    return state.updates if state is not None else 0


class Driver:
    """Sends a life's goals on schedule, asks for results, cancels; runs in the executor."""

    def __init__(self, clients: list[Any], goals: list[dict[str, Any]], linger: float,
                 period: float) -> None:
        from rclpy.task import Future
        self.clients, self.linger = clients, linger
        self.goals = [dict(g, uuid=None, ks=[], cb_uuids=[], cb_times=[], future=None,
                           result=None, result_at=None, outcome=None, status=None,
                           published=None, canceled=False) for g in goals]
        self.result_bound = {id(g): 30.0 + g['order'] * period * 5 for g in self.goals}
        self.update_at: list[Optional[float]] = [None] * len(clients)
        self.seen_updates = [filter_updates(c) for c in clients]
        self.start = time.monotonic()
        self.settled_at: Optional[float] = None
        self.finished = Future()

    def on_feedback_for(self, goal: dict[str, Any]) -> Any:
        def on_feedback(msg: Any) -> None:
            goal['cb_times'].append(time.monotonic())
            goal['cb_uuids'].append(bytes(msg.goal_id.uuid))
            goal['ks'].append(int(msg.feedback.sequence[0]))
        return on_feedback

    def send(self, goal: dict[str, Any], now: float) -> None:
        from test_msgs.action import Fibonacci
        from unique_identifier_msgs.msg import UUID
        client = self.clients[goal['client']]
        goal_uuid = UUID(uuid=list(uuid.uuid4().bytes)) if goal['caller'] else None
        goal['upd_before'] = filter_updates(client)
        goal['future'] = client.send_goal_async(
            Fibonacci.Goal(order=goal['order']),
            feedback_callback=self.on_feedback_for(goal) if goal['cb'] else None,
            goal_uuid=goal_uuid)
        goal['sent_at'] = now
        # The UUID, before any response: rclpy keeps it per pending request.
        pending = getattr(client, '_goal_sequence_number_to_goal_id', {})
        if goal_uuid is None and pending:
            goal_uuid = next(reversed(pending.values()))
        goal['uuid'] = bytes(goal_uuid.uuid) if goal_uuid is not None else None
        self.note_updates(now)
        goal['upd_after'] = filter_updates(client)
        seen = self.update_at[goal['client']]
        goal['since_update_s'] = None if seen is None else round(now - seen, 3)

    def note_updates(self, now: float) -> None:
        for i, client in enumerate(self.clients):
            updates = filter_updates(client)
            if updates != self.seen_updates[i]:
                self.seen_updates[i], self.update_at[i] = updates, now

    def step(self) -> None:
        now = time.monotonic()
        self.note_updates(now)
        for goal in self.goals:
            if goal['outcome'] is not None:
                continue
            if goal['future'] is None:
                if now >= self.start + goal['at']:
                    self.send(goal, now)
                continue
            if not goal['future'].done():
                if now - goal['sent_at'] > RESPONSE_S:
                    goal['outcome'] = 'no response'
                continue
            handle = goal['future'].result()
            if not handle.accepted:
                goal['outcome'] = 'rejected'
                continue
            goal['uuid'] = bytes(handle.goal_id.uuid)
            if goal['result'] is None:
                goal['result'] = handle.get_result_async()
                goal['result'].add_done_callback(
                    lambda _f, g=goal: g.__setitem__('result_at', time.monotonic()))
            if goal['result'].done():
                response = goal['result'].result()
                sequence = response.result.sequence
                goal['status'] = int(response.status)
                goal['published'] = int(sequence[0]) if len(sequence) else 0
                goal['outcome'] = 'result'
            elif (goal['cancel'] is not None and not goal['canceled']
                  and now >= goal['sent_at'] + goal['cancel']):
                handle.cancel_goal_async()
                goal['canceled'] = True
            elif now - goal['sent_at'] > self.result_bound[id(goal)]:
                goal['outcome'] = 'no result'
        if any(goal['outcome'] is None for goal in self.goals):
            return
        if self.settled_at is None:
            self.settled_at = now
        # Feedback still on the way (a lost sample is resent after the writer's next heartbeat,
        # 3 s), within --linger; then a little more for anything that should not arrive.
        complete = all(len({k for k in g['ks'] if k < g['published']}) >= g['published']
                       for g in self.goals if g['cb'] and g['published'] is not None)
        waited = now - self.settled_at
        if (complete and waited >= 0.3) or waited >= self.linger + 0.3:
            if not self.finished.done():
                self.finished.set_result(round(waited, 2))

    def report(self) -> list[dict[str, Any]]:
        out = []
        for g in self.goals:
            own = g['uuid']
            out.append({
                'client': g['client'], 'goal': g['goal'], 'order': g['order'], 'cb': g['cb'],
                'caller': g['caller'], 'cancel_asked': g['canceled'],
                'uuid': own.hex() if own else None, 'outcome': g['outcome'] or 'unfinished',
                'status': g['status'], 'published_result': g['published'], 'ks': g['ks'],
                'foreign_cb': sum(1 for u in g['cb_uuids'] if u != own),
                'after_result': sum(1 for t in g['cb_times']
                                    if g['result_at'] is not None and t > g['result_at']),
                'upd_before': g.get('upd_before'), 'upd_after': g.get('upd_after'),
                'since_update_s': g.get('since_update_s'),
                'sent_s': round(g['sent_at'] - self.start, 3) if 'sent_at' in g else None})
        return out


def role_life(action: str, config: str, spec: str, linger: float, depth: int,
              period: float) -> int:
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from harness.client import filter_counters, make_client, probe, recording_feedback

    life = json.loads(spec)
    t0 = time.monotonic()
    node = Node(f'cft_differential_{uuid.uuid4().hex[:8]}')
    qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
    clients = []
    for _ in range(life['clients']):
        client = make_client(node, config, action, qos)
        client.__class__ = recording_feedback(type(client))  # records every feedback taken from rcl
        client.feedback_taken = []
        clients.append(client)
    executor = (MultiThreadedExecutor() if life['executor'] == 'multi'
                else SingleThreadedExecutor())
    executor.add_node(node)
    report: dict[str, Any] = {'executor': life['executor'], 'clients': life['clients']}
    try:
        for client in clients:
            if not probe(node, executor, client, timeout=PROBE_S):
                say('RESULT', json.dumps({**report, 'failed': 'probe: no round trip'}))
                return 0
        report['ready_s'] = round(time.monotonic() - t0, 2)
        driver = Driver(clients, life['goals'], linger, period)
        timer = node.create_timer(0.01, driver.step)
        bound = (max(g['at'] for g in life['goals']) + RESPONSE_S
                 + max(driver.result_bound.values()) + linger + 10.0)
        executor.spin_until_future_complete(driver.finished, timeout_sec=bound)
        timer.cancel()
        report['linger_s'] = driver.finished.result() if driver.finished.done() else None
        goals = driver.report()
        report['goals'] = goals
        report['taken'] = []
        for i, client in enumerate(clients):
            own = [g for g in goals if g['client'] == i and g['uuid']]
            with_cb = {bytes.fromhex(g['uuid']) for g in own if g['cb']}
            without = {bytes.fromhex(g['uuid']) for g in own if not g['cb']}
            taken = [u for u, _k in client.feedback_taken]
            report['taken'].append({
                'all': len(taken), 'own_cb': sum(u in with_cb for u in taken),
                'own_no_cb': sum(u in without for u in taken),
                'other': sum(u not in with_cb and u not in without for u in taken),
                **filter_counters(client)})
        report['life_s'] = round(time.monotonic() - t0, 2)
        say('RESULT', json.dumps(report))
    finally:
        executor.shutdown(timeout_sec=2)
        for client in clients:
            client.destroy()
        node.destroy_node()
    return 0


#: The child processes of this script: ``differential.py _role NAME ARGS...``.
ROLES = {'life': role_life}


# ==================================================================================================
# The harness
# ==================================================================================================

class Differential:
    """One server, the configurations in turn, and everything they reported."""

    def __init__(self, opts: argparse.Namespace) -> None:
        self.opts = opts
        self.action = f'/cft_differential_{uuid.uuid4().hex[:8]}'
        self.env = plain_env(opts.domain)
        self.lock = threading.Lock()
        self.lives: dict[str, list[dict[str, Any]]] = {}
        self.published: dict[str, int] = {}  # goal UUID (hex) -> feedback the server published
        self.crashes: list[dict[str, Any]] = []
        self.outages: list[tuple[float, float]] = []
        self.server: Optional[Proc] = None
        self.server_dir = ''
        self.guard_status = ''
        self.life_bound = (PROBE_S * 2 + 1.0 + RESPONSE_S + 30.0
                           + opts.orders[1] * opts.period * 5 + opts.linger + 30.0)

    # --- the server ---------------------------------------------------------------------------

    def start_server(self) -> bool:
        o = self.opts
        self.server_dir = tempfile.mkdtemp(prefix='cft_differential_')
        depth = ['--depth', str(o.depth)] if o.depth else []
        argv = [*guard_command(), *python_module(
            'harness.server', self.action, o.period, *depth, '--result-timeout', o.result_timeout,
            '--executor', 'multi')]
        self.server = Proc('server', argv, self.env, cwd=self.server_dir, core=True)
        ready = self.server.wait_for('READY', 60.0) is not None
        status = self.server.last('STATUS') or ''
        self.guard_status = status.split(' ', 2)[2] if status.count(' ') >= 2 else status
        say(f'server pid {self.server.pid}, domain {o.domain}, guard: {self.guard_status or "?"}: '
            f'{"ready" if ready else "NOT READY"}')
        return ready

    def collect_published(self) -> None:
        """Merge the server's per-goal counts (kept across a crash: the new server starts empty)."""
        assert self.server is not None
        if self.server.poll() is not None:
            return
        try:
            counts = self.server.request_json('goals', 'GOALS', 30.0)
        except (TimeoutError, ValueError):
            return
        with self.lock:
            self.published.update(counts)

    def stop_server(self) -> dict[str, Any]:
        assert self.server is not None
        stats: dict[str, Any] = {}
        if self.server.poll() is None:
            self.collect_published()
            try:
                stats = self.server.request_json('stats', 'STATS', 10.0)
            except (TimeoutError, ValueError):
                pass
        rc = self.server.stop()
        shutil.rmtree(self.server_dir, ignore_errors=True)
        return {'rc': rc, 'signal': signal_name(rc), **{k: stats.get(k) for k in (
            'published', 'accepted', 'late_ticks', 'cpu_s', 'guard', 'guard_calls',
            'guard_filter')}}

    def check_server(self, config: str, t0: float) -> bool:
        """Record and replace a dead server; False when no replacement came up."""
        assert self.server is not None
        if self.server.poll() is None:
            return True
        died = time.monotonic()
        self.server.wait(120.0)  # until its core is written
        rc = self.server.poll()
        core, frames = core_backtrace(self.server_dir, self.server.pid)
        crash = {'config': config, 'at_s': round(died - t0, 1), 'signal': signal_name(rc),
                 'core': core, 'backtrace': frames, 'tail': self.server.tail(15)}
        self.crashes.append(crash)
        say(f'  SERVER CRASHED ({crash["signal"]}) at {crash["at_s"]} s of {config}')
        shutil.rmtree(self.server_dir, ignore_errors=True)
        ok = self.start_server()
        self.outages.append((died - 1.0, time.monotonic()))
        return ok

    # --- the lives ----------------------------------------------------------------------------

    def life(self, config: str, slot: int, n: int) -> None:
        o = self.opts
        spec = life_spec(o.seed, slot, n, o)
        start = time.monotonic()
        proc = Proc(f'{config} {slot}.{n}',
                    python_module('benchmarks.differential', '_role', 'life', self.action, config,
                                  json.dumps(spec), o.linger, o.depth or 10, o.period),
                    self.env)
        try:
            line = proc.wait_for('RESULT', self.life_bound)
            proc.wait(15.0)  # it exits by itself after its report
        finally:
            rc = proc.stop()
        record: dict[str, Any] = {'slot': slot, 'n': n, 'start': start, 'end': time.monotonic(),
                                  'rc': rc}
        if line is None:
            record.update(failed='no result', tail=proc.tail(8))
        else:
            record.update(json.loads(line.split(' ', 1)[1]))
        if rc not in (0, None):
            record['client_exit'] = signal_name(rc)
        with self.lock:
            self.lives[config].append(record)

    def slot_loop(self, config: str, slot: int, end: float, count: Optional[int]) -> None:
        n = 0
        while time.monotonic() < end and (count is None or n < count):
            try:
                self.life(config, slot, n)
            except Exception as e:  # noqa: BLE001 (a harness error must not end the run)
                with self.lock:
                    self.lives[config].append({'slot': slot, 'n': n, 'failed': f'harness: {e!r}',
                                               'start': time.monotonic(),
                                               'end': time.monotonic()})
            n += 1

    def run_config(self, config: str, counts: Optional[list[int]]) -> float:
        """Run one configuration: for the duration, or the lives in ``counts`` per slot."""
        o = self.opts
        self.lives[config] = []
        t0 = time.monotonic()
        limit = o.duration if counts is None else max(2 * o.duration, o.duration + 120)
        end = t0 + limit
        slots = [threading.Thread(target=self.slot_loop,
                                  args=(config, s, end, None if counts is None else counts[s]),
                                  daemon=True) for s in range(o.slots)]
        for thread in slots:
            thread.start()
            time.sleep(0.2)  # staggered starts
        next_progress = t0 + PROGRESS_S
        alive = True
        hard_end = end + self.life_bound + 30.0
        while any(t.is_alive() for t in slots) and time.monotonic() < hard_end:
            time.sleep(0.5)
            if alive:
                alive = self.check_server(config, t0)
            if time.monotonic() >= next_progress:
                next_progress += PROGRESS_S
                self.collect_published()
                self.progress(config, time.monotonic() - t0, limit, counts)
        self.collect_published()
        return time.monotonic() - t0

    def progress(self, config: str, elapsed: float, limit: float,
                 counts: Optional[list[int]]) -> None:
        with self.lock:
            summary = summarize_config(config, self.lives, self.published, self.outages)
        target = f'/{sum(counts)} lives' if counts is not None else f' lives of {limit:.0f} s'
        say(f'  [{config}] {elapsed:.0f} s: {summary["lives"]}{target} '
            f'({summary["lives_failed"]} failed), {summary["goals"]} goals, '
            f'{summary["delivered"]} delivered, lost {summary["lost"]}, foreign '
            f'{summary["foreign"]}, fewer than plain {summary.get("fewer_than_plain", "-")}, '
            f'server crashes {len(self.crashes)}')

    def run(self) -> dict[str, Any]:
        o = self.opts
        if not self.start_server():
            return {'error': 'server not ready', 'server_tail': self.server.tail()
                    if self.server else ''}
        walls: dict[str, float] = {}
        final: dict[str, Any] = {}
        try:
            counts: Optional[list[int]] = None
            for config in o.configs:
                say(f'[{config}] ' + (f'{o.duration:g} s, {o.slots} slots' if counts is None
                                      else f'the same {sum(counts)} lives, per slot {counts}'))
                walls[config] = round(self.run_config(config, counts), 1)
                if counts is None:
                    counts = [sum(1 for life in self.lives[config] if life['slot'] == s)
                              for s in range(o.slots)]
                time.sleep(1.0)  # let discovery retire this configuration's readers
        finally:
            final = self.stop_server()
        summaries = {config: summarize_config(config, self.lives, self.published, self.outages)
                     for config in self.lives}
        add_ratios(summaries)
        for config, summary in summaries.items():
            summary['wall_s'] = walls.get(config)
            summary['server_crashes'] = sum(c['config'] == config for c in self.crashes)
        return {'summaries': summaries, 'crashes': self.crashes, 'server_final': final,
                'guard_status': self.guard_status, 'action': self.action,
                'details': goal_details(self.lives, self.published, self.outages),
                'failed_lives': [{k: v for k, v in life.items() if k != 'goals'}
                                 for lives in self.lives.values() for life in lives
                                 if 'failed' in life][:20],
                'lives': self.lives, 'published': self.published, 'outages': self.outages}


# ==================================================================================================
# The accounting
# ==================================================================================================

def disrupted(life: dict[str, Any], outages: list[tuple[float, float]]) -> bool:
    """Whether a life overlapped a server outage (from its crash to its replacement)."""
    return any(life['start'] <= ready and life['end'] >= died for died, ready in outages)


def counted_goals(lives: list[dict[str, Any]], outages: list[tuple[float, float]]) -> dict:
    """(slot, life, client, goal) -> goal record, over lives that finished and saw no outage."""
    goals = {}
    for life in lives:
        if 'failed' in life or disrupted(life, outages):
            continue
        for g in life.get('goals', []):
            goals[(life['slot'], life['n'], g['client'], g['goal'])] = g
    return goals


def published_of(goal: dict[str, Any], published: dict[str, int]) -> Optional[int]:
    """What the server published for a goal: its own count, else the count in the result."""
    if goal['uuid'] and goal['uuid'] in published:
        return published[goal['uuid']]
    return goal['published_result']


def delivered_of(goal: dict[str, Any]) -> set[int]:
    return set(goal['ks'])


def common(goal: dict[str, Any], plain: dict[str, Any], published: dict[str, int]
           ) -> tuple[set[int], set[int]]:
    """The k delivered by each run of a goal, below what the server published in both runs.

    A canceled goal publishes as many messages as its cancel took to act, which differs by run;
    only the messages both runs published can be compared.
    """
    bound = min(published_of(goal, published) or 0, published_of(plain, published) or 0)
    return ({k for k in goal['ks'] if k < bound}, {k for k in plain['ks'] if k < bound})


def comparable(goal: dict[str, Any], plain: Optional[dict[str, Any]]) -> bool:
    return (plain is not None and goal['cb'] and goal['outcome'] == 'result'
            and plain['outcome'] == 'result')


def after_update(config: str, goal: dict[str, Any]) -> bool:
    """Whether a goal came with a filter update: sent within UPDATE_WINDOW_S after one of its
    client's, in ``goals`` mode or with an untagged UUID of the caller's in ``client`` mode."""
    updated = (goal['upd_after'] or 0) >= 1 and goal['since_update_s'] is not None \
        and goal['since_update_s'] <= UPDATE_WINDOW_S
    return updated and (config == 'goals' or (config == 'client' and goal['caller']))


def compare(config: str, goal: dict[str, Any], plain: Optional[dict[str, Any]],
            published: dict[str, int]) -> Optional[str]:
    """How a cft goal fell short of plain's: None, or where the k it lacks are.

    ``'first after update'``: it lacks ``k = 0`` and was sent within :data:`UPDATE_WINDOW_S` after
    a filter update of its client, in ``goals`` mode or with an untagged UUID of the caller's in
    ``client`` mode; ``'at start'``: all it lacks comes before the first k it got; ``'gaps'``:
    anything else.
    """
    if plain is None or not comparable(goal, plain):
        return None
    mine, theirs = common(goal, plain, published)
    if len(mine) >= len(theirs):
        return None
    missing = theirs - mine
    if 0 in missing and after_update(config, goal):
        return 'first after update'
    return 'at start' if not mine or max(missing) < min(mine) else 'gaps'


def summarize_config(config: str, lives: dict[str, list[dict[str, Any]]],
                     published: dict[str, int], outages: list[tuple[float, float]]
                     ) -> dict[str, Any]:
    """The figures of one configuration, compared goal by goal with plain rclpy's."""
    mine = lives.get(config, [])
    goals = counted_goals(mine, outages)
    plain = counted_goals(lives.get('rclpy', []), outages) if config != 'rclpy' else {}
    reasons: dict[str, int] = {}
    for life in mine:
        if 'failed' in life:
            reasons[life['failed']] = reasons.get(life['failed'], 0) + 1
    s: dict[str, Any] = {
        'config': config, 'lives': len(mine), 'lives_failed': sum(reasons.values()),
        'failure_reasons': reasons,
        'lives_disrupted': sum(1 for life in mine if disrupted(life, outages)),
        'lives_multi': sum(life.get('executor') == 'multi' for life in mine),
        'lives_two_clients': sum(life.get('clients') == 2 for life in mine),
        'goals': len(goals), 'goals_cb': sum(g['cb'] for g in goals.values()),
        'goals_caller_uuid': sum(g['caller'] for g in goals.values()),
        'goals_cancel_asked': sum(g['cancel_asked'] for g in goals.values()),
        'outcomes': {}, 'delivered': 0, 'duplicates': 0, 'after_result': 0, 'published_cb': 0,
        'lost': 0, 'goals_with_loss': 0, 'lost_first': 0, 'lost_first_after_update': 0,
        'foreign_cb': 0,
        'taken_other': 0, 'taken_own_no_cb': 0, 'filter_updates': 0, 'filters_inactive': 0}
    for g in goals.values():
        s['outcomes'][g['outcome']] = s['outcomes'].get(g['outcome'], 0) + 1
        s['foreign_cb'] += g['foreign_cb']
        if not g['cb']:
            continue
        ks = delivered_of(g)
        s['delivered'] += len(ks)
        s['duplicates'] += len(g['ks']) - len(ks)
        s['after_result'] += g['after_result']
        count = published_of(g, published)
        if count is None or g['outcome'] != 'result':
            continue
        s['published_cb'] += count
        lost = count - len({k for k in ks if k < count})
        s['lost'] += lost
        s['goals_with_loss'] += lost > 0
        s['lost_first'] += count > 0 and 0 not in ks
        s['lost_first_after_update'] += (count > 0 and 0 not in ks and config != 'rclpy'
                                         and after_update(config, g))
    for life in mine:
        for taken in life.get('taken', []):
            s['taken_other'] += taken['other']
            s['taken_own_no_cb'] += taken['own_no_cb']
            s['filter_updates'] += taken.get('updates', 0)
            s['filters_inactive'] += config != 'rclpy' and not taken.get('active', False)
    # Plain rclpy takes every goal's feedback by design: only its callbacks can be foreign.
    s['foreign'] = s['foreign_cb'] + (0 if config == 'rclpy'
                                      else s['taken_other'] + s['taken_own_no_cb'])
    if config != 'rclpy':
        verdicts = [compare(config, g, plain.get(key), published) for key, g in goals.items()]
        pairs = [common(g, plain[key], published) for key, g in goals.items()
                 if comparable(g, plain.get(key))]
        s.update({
            'comparable': len(pairs),
            'delivered_comparable': sum(len(mine) for mine, _ in pairs),
            'plain_delivered_comparable': sum(len(theirs) for _, theirs in pairs),
            'fewer_than_plain': sum(v is not None for v in verdicts),
            'fewer_first_after_update': verdicts.count('first after update'),
            'fewer_at_start': verdicts.count('at start'),
            'fewer_gaps': verdicts.count('gaps'),
            'missing_vs_plain': sum(1 for mine, theirs in pairs if theirs - mine),
            'more_than_plain': sum(1 for mine, theirs in pairs if len(mine) > len(theirs)),
            'goals_not_in_plain': sum(1 for k in goals if k not in plain)})
    return s


def add_ratios(summaries: dict[str, dict[str, Any]]) -> None:
    plain = summaries.get('rclpy')
    if not plain:
        return
    for s in summaries.values():
        if s['config'] == 'rclpy':
            continue
        s['ratio_to_plain'] = {
            'delivered_comparable': (s['delivered_comparable'] / s['plain_delivered_comparable']
                                     if s['plain_delivered_comparable'] else None),
            'lost': s['lost'] / plain['lost'] if plain['lost'] else None,
            'taken_other': (s['taken_other'] / plain['taken_other']
                            if plain['taken_other'] else None)}


def goal_details(lives: dict[str, list[dict[str, Any]]], published: dict[str, int],
                 outages: list[tuple[float, float]]) -> list[dict[str, Any]]:
    """Every goal that fell short of plain, had a foreign message or lost feedback, per config."""
    plain = counted_goals(lives.get('rclpy', []), outages)
    out = []
    for config, mine in lives.items():
        for key, g in counted_goals(mine, outages).items():
            count = published_of(g, published)
            verdict = compare(config, g, plain.get(key), published) if config != 'rclpy' else None
            lost = (count - len({k for k in g['ks'] if k < count})
                    if g['cb'] and count is not None and g['outcome'] == 'result' else 0)
            if verdict is None and not g['foreign_cb'] and not lost:
                continue
            entry = {'config': config, 'key': list(key), 'verdict': verdict, 'lost': lost,
                     'published': count, **{k: g[k] for k in (
                         'uuid', 'caller', 'cancel_asked', 'order', 'status', 'ks', 'foreign_cb',
                         'after_result', 'upd_before', 'upd_after', 'since_update_s', 'sent_s')}}
            if key in plain and config != 'rclpy':
                entry['plain_ks'] = plain[key]['ks']
                entry['plain_published'] = published_of(plain[key], published)
            out.append(entry)
    return out


# ==================================================================================================
# Presentation
# ==================================================================================================

def markdown_table(summaries: dict[str, dict[str, Any]]) -> str:
    rows = ['| config | client lives (failed) | goals | with callback | feedback delivered '
            '| fewer than plain (first after filter update / other at start / gaps) | foreign '
            '| lost vs published (goals) | goals that lost k = 0 (after a filter update) '
            '| server crashes |',
            '|---|---|---|---|---|---|---|---|---|---|']
    for s in summaries.values():
        fewer = ('-' if s['config'] == 'rclpy' else
                 f'{s["fewer_than_plain"]} ({s["fewer_first_after_update"]} / '
                 f'{s["fewer_at_start"]} / {s["fewer_gaps"]})')
        foreign = (f'{s["foreign"]} (unfiltered: {s["taken_other"]} taken)'
                   if s['config'] == 'rclpy' else str(s['foreign']))
        rows.append(f'| {s["config"]} | {s["lives"]} ({s["lives_failed"]}) | {s["goals"]} | '
                    f'{s["goals_cb"]} | {s["delivered"]} | {fewer} | {foreign} | '
                    f'{s["lost"]} of {s["published_cb"]} ({s["goals_with_loss"]}) | '
                    f'{s["lost_first"]} ({s["lost_first_after_update"]}) | '
                    f'{s["server_crashes"]} |')
    rows += ['', '| ratio to plain | delivered on the same goals | lost '
             '| feedback of others taken |', '|---|---|---|---|']
    for s in summaries.values():
        r = s.get('ratio_to_plain')
        if r:
            rows.append(f'| {s["config"]} | {fmt(r["delivered_comparable"], ".3f")} | '
                        f'{fmt(r["lost"], ".3f")} | {fmt(r["taken_other"], ".3f")} |')
    return '\n'.join(rows)


def text_table(summaries: dict[str, dict[str, Any]]) -> str:
    rows = [('config', 'lives', 'failed', 'goals', 'with cb', 'delivered', 'fewer/plain',
             'first-after-upd', 'at start', 'gaps', 'foreign', 'lost', 'of published', 'crashes')]
    for s in summaries.values():
        rows.append((s['config'], str(s['lives']), str(s['lives_failed']), str(s['goals']),
                     str(s['goals_cb']), str(s['delivered']), str(s.get('fewer_than_plain', '-')),
                     *(str(s.get(k, '-')) for k in ('fewer_first_after_update', 'fewer_at_start',
                                                    'fewer_gaps')), str(s['foreign']),
                     str(s['lost']), str(s['published_cb']), str(s['server_crashes'])))
    return grid(rows)


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--duration', type=float, default=60.0,
                        help="seconds of plain rclpy; each cft config runs the same lives")
    parser.add_argument('--seed', type=int, default=None, help='the workload (default: random)')
    parser.add_argument('--slots', type=int, default=8, help='client processes at a time')
    parser.add_argument('--configs', default=','.join(CONFIGS),
                        help="comma-separated, 'rclpy' first (default: rclpy,client,goals)")
    parser.add_argument('--out', metavar='PATH', help='write the results as JSON')
    parser.add_argument('--raw', metavar='PATH',
                        help='also write every life and goal record, and the server counts')
    parser.add_argument('--markdown', action='store_true', help='print a markdown table')
    parser.add_argument('--domain', type=int, default=88, help='ROS_DOMAIN_ID of every process')
    parser.add_argument('--period', type=float, default=0.02, help='server feedback period, s')
    parser.add_argument('--orders', type=int, nargs=2, default=[3, 40], metavar=('MIN', 'MAX'),
                        help='feedback messages per goal')
    parser.add_argument('--max-goals', type=int, default=3, help='goals per client, at most')
    parser.add_argument('--two-clients', type=float, default=0.3,
                        help='probability of two action clients in one process')
    parser.add_argument('--callback', type=float, default=0.75,
                        help='probability that a goal has a feedback callback')
    parser.add_argument('--caller', type=float, default=0.3,
                        help='probability of a caller-supplied (untagged uuid4) goal_uuid')
    parser.add_argument('--cancel', type=float, default=0.25,
                        help='probability that a goal is canceled')
    parser.add_argument('--linger', type=float, default=4.0,
                        help='seconds a client waits after its last result for missing feedback')
    parser.add_argument('--depth', type=int, default=None,
                        help="every queue's depth (default: rclpy's keep-last 10)")
    parser.add_argument('--result-timeout', type=int, default=15,
                        help='seconds a finished goal stays on the server')
    opts = parser.parse_args(argv)
    opts.configs = [c.strip() for c in opts.configs.split(',') if c.strip()]
    if not opts.configs or opts.configs[0] != 'rclpy' or set(opts.configs) - set(CONFIGS) \
            or len(set(opts.configs)) != len(opts.configs):
        parser.error(f"--configs: distinct names of {', '.join(CONFIGS)}, starting with rclpy")
    if opts.seed is None:
        opts.seed = random.randrange(2 ** 31)
    return opts


def main(argv: list[str]) -> int:
    """Run the benchmark with the command line ``argv``."""
    opts = parse_args(argv)
    header = {'date_utc': datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M'),
              'machine': machine_line(), 'environment': environment_facts(),
              'command': 'python -m benchmarks.differential ' + ' '.join(argv),
              'options': {k: v for k, v in vars(opts).items()}}
    say(json.dumps({k: header[k] for k in ('date_utc', 'machine', 'command')}))
    say(f'seed {opts.seed}')
    started = time.monotonic()
    result = {'header': header, **Differential(opts).run()}
    result['header']['wall_s'] = round(time.monotonic() - started, 1)
    result['header']['finished_utc'] = datetime.datetime.now(
        datetime.timezone.utc).strftime('%Y-%m-%d %H:%M')
    raw = {key: result.pop(key, None) for key in ('lives', 'published', 'outages')}
    for path, content, indent in ((opts.out, result, 1), (opts.raw, raw, None)):
        if path:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            Path(path).write_text(json.dumps(content, indent=indent, default=str))
            say(f'wrote {path}')
    if 'error' in result:
        say(f'error: {result["error"]}')
        return 1
    say('')
    say(markdown_table(result['summaries']) if opts.markdown else text_table(result['summaries']))
    return 0


if __name__ == '__main__':
    sys.exit(main_or_role(main, ROLES))
