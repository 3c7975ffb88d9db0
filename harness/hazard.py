# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""One cell of the hazard matrix: a filter event against a Fast DDS action server, guard on or off.

``benchmarks/hazard.py`` runs the matrix (it documents the events, periods and payloads); the
guard's tests run its ``update`` cell. :func:`run_cell` starts the server (:mod:`harness.server`,
rclpy's default queues, in a fresh directory so that a crash leaves its core there), an ordinary
client that keeps one goal running, and the client of the cell's events; those clients are the
roles of this module: ``python -m harness.hazard ROLE ARGS...``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import threading
import time
import uuid
from typing import Any, Callable, Optional

from harness.crash import (alive, core_backtrace, plain_env, server_command, server_env,
                           signal_name, stats_of)
from harness.domain import unused_domain
from harness.proc import Proc, python_module, run_role
from harness.report import say
from harness.server import HEADER

EVENTS = ('update', 'destroy', 'create', 'exit')
# int32 elements after the server's 3-element header (index, publish time): 3 or 2500 in all
PAYLOADS = {'small': 0, '10k': 2500 - HEADER}
# Two expressions that match no goal; the update role alternates them.
NEVER = ('goal_id.uuid[0] = 0 AND goal_id.uuid[0] = 1',
         'goal_id.uuid[0] = 0 AND goal_id.uuid[0] = 2')
# int32 maximum: a goal of this order keeps the server publishing for the whole cell.
FOREVER = 2 ** 31 - 1


# ==================================================================================================
# Child processes (roles). Each prints lines that start with a capitalised keyword.
# ==================================================================================================

def role_goal(action: str) -> int:
    """An ordinary (unfiltered) client that keeps one goal running, and then only waits.

    It stops spinning after the first feedback: the server keeps publishing to its reader, and
    this process costs no CPU taking samples it does not need.
    """
    import rclpy
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from test_msgs.action import Fibonacci
    node = Node('hazard_goal')
    client = ActionClient(node, Fibonacci, action)
    if not client.wait_for_server(timeout_sec=20.0):
        say('NO_SERVER')
        return 1
    got = threading.Event()
    future = client.send_goal_async(Fibonacci.Goal(order=FOREVER),
                                    feedback_callback=lambda _m: got.set())
    rclpy.spin_until_future_complete(node, future, timeout_sec=20.0)
    if not future.done() or not future.result().accepted:
        say('NOT_ACCEPTED')
        return 1
    deadline = time.monotonic() + 20.0
    while not got.is_set() and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    say('FEEDBACK' if got.is_set() else 'NO_FEEDBACK')
    sys.stdin.read()  # until the harness closes our stdin
    return 0


def _event_loop(count: int, server_pid: int, one: Callable[[int], None]) -> int:
    """Run ``one(i)`` for i in 1..count, checking the server after each; print RESULT."""
    say('EVENTS_START')
    start = time.monotonic()
    for i in range(1, count + 1):
        one(i)
        if not alive(server_pid):
            say('RESULT died_after', i, f'{time.monotonic() - start:.2f}')
            return 0
    say('RESULT survived', count, f'{time.monotonic() - start:.2f}')
    return 0


def role_update(action: str, count: int, interval: float, server_pid: int) -> int:
    """A live filtered reader whose filter changes ``count`` times, every ``interval`` s."""
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from test_msgs.action import Fibonacci

    from cft_action import _rcl
    node = Node('hazard_update')
    client = ActionClient(node, Fibonacci, action)
    ptr, reason = _rcl.action_feedback_subscription(client._client_handle.pointer,
                                                    node.resolve_topic_name(action))
    if ptr is None:
        say('ERROR no feedback subscription:', reason)
        return 2
    # The class a default client uses (the library's own, unless CFT_ACTION_WRITER_FILTERING=any).
    guarded = os.environ.get('CFT_ACTION_WRITER_FILTERING', 'guarded') == 'guarded'
    filter_class = _rcl.UUID_FILTER_CLASS if guarded else None
    # The first filter recreates the reader: before use.
    _rcl.set_content_filter(ptr, NEVER[0], filter_class=filter_class)
    if not client.wait_for_server(timeout_sec=20.0):
        say('NO_SERVER')
        return 1
    time.sleep(1.0)  # let discovery carry the filtered reader to the server

    def update(i: int) -> None:
        _rcl.set_content_filter(ptr, NEVER[i % 2], filter_class=filter_class)
        time.sleep(interval)

    return _event_loop(count, server_pid, update)


def _filtered_client(node: Any, action: str) -> Any:
    from test_msgs.action import Fibonacci

    from cft_action import ActionClient
    client = ActionClient(node, Fibonacci, action, feedback_filter='client')
    if not client.feedback_filter_state.active:
        raise RuntimeError(f'filter not active: {client.feedback_filter_state.reason}')
    return client


def role_destroy(action: str, count: int, server_pid: int, settle: float) -> int:
    """Filtered clients created, matched and destroyed, one after the other."""
    from rclpy.node import Node
    node = Node('hazard_destroy')

    def destroy(_i: int) -> None:
        client = _filtered_client(node, action)
        if not client.wait_for_server(timeout_sec=10.0):
            say('WARN server not seen')
        time.sleep(settle)  # let the server's writer match the filtered reader
        client.destroy()
        time.sleep(settle)  # and process its removal

    return _event_loop(count, server_pid, destroy)


def role_create(action: str, count: int, server_pid: int, settle: float) -> int:
    """Filtered clients created and kept; afterwards waits for stdin to close."""
    from rclpy.node import Node
    node = Node('hazard_create')
    kept = []

    def create(_i: int) -> None:
        client = _filtered_client(node, action)
        kept.append(client)
        if not client.wait_for_server(timeout_sec=10.0):
            say('WARN server not seen')
        time.sleep(settle)

    rc = _event_loop(count, server_pid, create)
    sys.stdin.read()  # the harness stops the server before this process exits
    return rc


def role_exitproc(action: str, k: int, settle: float) -> int:
    """Create ``k`` filtered clients, print READY, then exit normally (rclpy shuts down)."""
    from rclpy.node import Node
    node = Node('hazard_exit')
    kept = [_filtered_client(node, action) for _ in range(k)]
    if not kept[-1].wait_for_server(timeout_sec=15.0):
        say('WARN server not seen')
    time.sleep(settle)
    say('READY', len(kept))
    return 0


#: The child processes of a cell: ``python -m harness.hazard NAME ARGS...``.
ROLES: dict[str, Callable[..., int]] = {
    'goal': role_goal, 'update': role_update, 'destroy': role_destroy, 'create': role_create,
    'exitproc': role_exitproc}


# ==================================================================================================
# The cell
# ==================================================================================================

class Cell:
    """One cell of the matrix: event x period x payload x guard."""

    def __init__(self, event: str, period: float, payload: str, guarded: bool,
                 bound: int) -> None:
        self.event, self.period, self.payload, self.guarded = event, period, payload, guarded
        self.bound = bound

    def label(self) -> str:
        return (f'{self.event} period={self.period * 1000:g}ms payload={self.payload} '
                f'guard={"on" if self.guarded else "off"}')


def run_cell(cell: Cell, opts: argparse.Namespace, domain: Optional[int] = None) -> dict[str, Any]:
    """Run one cell and return what happened. Asserts nothing; never retries.

    ``opts`` needs ``interval``, ``settle``, ``k`` and ``keep_cores``; ``domain`` is an unused one
    (:func:`harness.domain.unused_domain`) unless given.
    """
    domain = domain or unused_domain()
    action = f'hz_{uuid.uuid4().hex[:10]}'
    workdir = tempfile.mkdtemp(prefix='cft_hazard_')
    started: list[Proc] = []
    outcome: dict[str, Any] = {
        'event': cell.event, 'period_ms': cell.period * 1000, 'payload': cell.payload,
        'guard': cell.guarded, 'bound': cell.bound, 'domain': domain,
        'k': opts.k if cell.event == 'exit' else None}
    t_cell = time.monotonic()

    def start(name: str, args: list[str], env: dict[str, str], **kw: Any) -> Proc:
        proc = Proc(name, args, env, **kw)
        started.append(proc)
        return proc

    role = python_module('harness.hazard')
    try:
        server = start('server', server_command(action, cell.period, PAYLOADS[cell.payload]),
                       server_env(domain, cell.guarded), cwd=workdir, core=True)
        status = server.wait_for('STATUS', 60.0)
        outcome['guard_status'] = status.split(' ', 2)[2] if status else None
        if not server.wait_for('READY', 60.0):
            outcome['error'] = 'server not ready'
            return outcome
        goal = start('goal', [*role, 'goal', action], plain_env(domain))
        first = goal.wait_for('FEEDBACK', 60.0) or goal.wait_for('NO', 0.1)
        if first != 'FEEDBACK':
            outcome['error'] = f'goal client: {first or "no answer"}'
            return outcome
        before = server.wait_for('STATS', 5.0, after=len(server.lines))
        settle = str(opts.settle)
        events_start = time.monotonic()
        if cell.event == 'exit':
            result = run_exit_events(cell, opts, action, domain, server, started)
        else:
            args = {'update': [str(cell.bound), str(opts.interval), str(server.pid)],
                    'destroy': [str(cell.bound), str(server.pid), settle],
                    'create': [str(cell.bound), str(server.pid), settle]}[cell.event]
            per_event = {'update': opts.interval + 0.05, 'destroy': 2 * opts.settle + 3.0,
                         'create': opts.settle + 3.0}[cell.event]
            events = start(cell.event, [*role, cell.event, action, *args], plain_env(domain))
            line = events.wait_for('RESULT', 60.0 + cell.bound * per_event)
            if line is None:
                result = {'error': f'{cell.event} client gave no result in time',
                          'client_rc': events.poll()}
            else:
                words = line.split()
                result = {'survived': words[1] == 'survived', 'events': int(words[2]),
                          'seconds': float(words[3])}
        outcome.update(result)
        outcome['events_wall_s'] = round(time.monotonic() - events_start, 1)
        # The server: alive, or dead with what signal, and its backtrace.
        if result.get('survived') is False:
            server.wait(120.0)  # a crashing server is gone from /proc before its core is written
        after_line = server.all('STATS')[-1] if server.all('STATS') else None
        if server.poll() is None:
            server.send('stats')
            after_line = server.wait_for('STATS', 5.0, after=len(server.lines)) or after_line
            outcome['server'] = 'alive'
        else:
            server.wait(10.0)
            outcome['server'] = signal_name(server.poll())
        s0, s1 = stats_of(before), stats_of(after_line)
        if s0 and s1 and s1['t'] > s0['t']:
            outcome['feedback_per_s'] = round((s1['published'] - s0['published'])
                                              / (s1['t'] - s0['t']))
            outcome['late_ticks'] = s1['late_ticks'] - s0['late_ticks']
        if s1:
            outcome['guard_calls'] = s1.get('guard_calls')
        return outcome
    finally:
        server_dead_before_stop = started and started[0].poll() is not None
        for proc in started:  # the server first, so that client exits are not counted
            proc.stop()
        if started and started[0].name == 'server':
            server = started[0]
            if not server_dead_before_stop and server.poll() not in (0, None):
                outcome['server_at_stop'] = signal_name(server.poll())
            exit_status = server.poll()
            if exit_status is not None and exit_status < 0:
                core, frames = core_backtrace(workdir, server.pid, keep=opts.keep_cores)
                outcome['core'] = core
                outcome['backtrace'] = frames
                if core is None:
                    outcome['backtrace_note'] = 'no core file (see core_pattern / ulimit)'
            tails = [p.tail() for p in started if p.poll() not in (0, None)
                     or 'error' in outcome]
            if tails:
                outcome['logs'] = tails
            # Anything the guard itself said (it is silent when active on a known Fast DDS).
            outcome['guard_messages'] = [line for line in server.lines
                                         if line.startswith('[cft_action guard')]
        if not opts.keep_cores:
            shutil.rmtree(workdir, ignore_errors=True)
        outcome['cell_wall_s'] = round(time.monotonic() - t_cell, 1)


def run_exit_events(cell: Cell, opts: argparse.Namespace, action: str, domain: int,
                    server: Proc, started: list[Proc]) -> dict[str, Any]:
    """One process with ``k`` filtered readers after the other, each exiting normally."""
    role = python_module('harness.hazard')
    t0 = time.monotonic()
    for i in range(1, cell.bound + 1):
        proc = Proc(f'exit{i}', [*role, 'exitproc', action, str(opts.k), str(opts.settle)],
                    plain_env(domain))
        started.append(proc)
        ready = proc.wait_for('READY', 60.0 + 2.0 * opts.k)
        if server.poll() is not None or not alive(server.pid):
            proc.stop()
            return {'survived': False, 'events': i - 1, 'during': f'creation in process {i}',
                    'seconds': round(time.monotonic() - t0, 2)}
        proc.close_stdin()
        rc = proc.wait(30.0)
        if ready is None or rc is None:
            proc.stop()
            return {'error': f'exit process {i}: ' + ('not ready' if ready is None else
                                                      'did not exit'),
                    'events': i - 1, 'survived': False}
        started.remove(proc)
        time.sleep(max(opts.settle, 1.0))  # let the server process the removals
        if server.poll() is not None or not alive(server.pid):
            return {'survived': False, 'events': i, 'seconds': round(time.monotonic() - t0, 2)}
    return {'survived': True, 'events': cell.bound, 'seconds': round(time.monotonic() - t0, 2)}


def describe(outcome: dict[str, Any]) -> str:
    if 'error' in outcome:
        return f'inconclusive: {outcome["error"]}'
    if outcome.get('survived'):
        return f'survived {outcome["events"]}'
    during = f', during {outcome["during"]}' if outcome.get('during') else ''
    return f'crashed after {outcome["events"]} ({outcome.get("server", "?")}{during})'


if __name__ == '__main__':
    sys.exit(run_role(sys.argv[1:], ROLES))
