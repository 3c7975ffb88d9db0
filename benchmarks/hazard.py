# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The hazard matrix: which filter events crash a Fast DDS action server, guard on and off.

With Fast DDS 2.14 (Jazzy), events at a filtered reader that the server's feedback writer must
process can segfault the **server** (eProsima/Fast-DDS issue 4878; ``docs/SAFETY.md``). This script
reproduces them, cell by cell, with and without the guard (:mod:`cft_action.guard`):

- ``update``: a live filtered reader changes its filter every ``--interval`` s (two expressions
  that match nothing, alternated, so each update is a real change), up to ``--updates`` times;
- ``destroy``: a filtered ``cft_action.ActionClient`` (``client`` mode) is created, matched and
  destroyed, up to ``--destroys`` times, in one process;
- ``create``: filtered clients are created and kept, up to ``--creates`` of them, in one process
  (the server is stopped before that process exits, so its exit is not counted here);
- ``exit``: a process creates ``--k`` filtered clients, then exits normally; up to ``--exits``
  processes, one after the other.

The server publishes feedback every PERIOD s (``--periods``, default 0.0005 0.01 0.1) from a ticker
thread to one goal that an ordinary, unfiltered client keeps running; the feedback carries
``small`` (one int32) or ``10k`` (2500 int32, 10,000 bytes) payload (``--payloads``). Each cell runs
to the first server crash or to its bound of events, with the guard ``on`` and ``off``
(``--guard``). A crashed server's core (``ulimit -c unlimited`` in the server, cwd a fresh
directory) is read with gdb for the crashing thread's backtrace; without gdb or a core, the exit
signal is all that is recorded. A crash is evidence: cells are never retried.

Each cell has a ROS domain of its own (random, 1..101), localhost-only discovery and a unique action
name. Every wait is bounded; every process started is stopped by this script, by its pid.

Examples::

    python benchmarks/hazard.py --events update --periods 0.0005 --payloads small --updates 50
    python benchmarks/hazard.py --events update destroy --periods 0.0005 0.01 --payloads small \\
        --updates 200 --destroys 30 --json /tmp/hazard.json

The child processes are this same file: ``hazard.py _role ROLE ARGS...``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import random
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from typing import Any, Callable, Optional

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

THIS = Path(__file__).resolve()
PYTHON = sys.executable

EVENTS = ('update', 'destroy', 'create', 'exit')
PAYLOADS = {'small': 0, '10k': 2499}  # int32 elements after the counter: 1 or 2500 in all
# Two expressions that match no goal; the update role alternates them.
NEVER = ('goal_id.uuid[0] = 0 AND goal_id.uuid[0] = 1',
         'goal_id.uuid[0] = 0 AND goal_id.uuid[0] = 2')
# int32 maximum: a goal of this order keeps the server publishing for the whole cell.
FOREVER = 2 ** 31 - 1


def say(*words: object) -> None:
    print(*words, flush=True)


# ==================================================================================================
# Child processes (roles). Each prints lines that start with a capitalised keyword.
# ==================================================================================================

def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, not yet reaped by its parent, counts as dead)."""
    try:
        with open(f'/proc/{pid}/stat') as f:
            state = f.read().rsplit(')', 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ('Z', 'X')


def _qos_kwargs(depth: int, side: str) -> dict[str, Any]:
    """Keep-last ``depth``, reliable, for every queue of an action server or client; {} for 0."""
    if depth <= 0:
        return {}
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    profile = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
    names = ['goal_service_qos_profile', 'result_service_qos_profile',
             'cancel_service_qos_profile', f'feedback_{side}_qos_profile']
    return {name: profile for name in names}


def guard_report() -> dict[str, Any]:
    import cft_action.guard as guard
    return {'active': guard.is_active(), 'status': guard.status(), 'calls': guard.call_counts()}


class TickingServer:
    """A Fibonacci action server whose ticker thread publishes feedback for every running goal.

    Goal ``order`` is the number of feedback messages (``FOREVER`` runs until canceled); each
    feedback ``sequence`` is ``[k] + [0] * pad``. A negative order is rejected; cancels are
    accepted. The result's ``sequence`` is ``[feedback messages published for this goal]``, so a
    client can count what it lost.
    """

    def __init__(self, node: Any, executor: Any, action: str, period: float, pad: int,
                 depth: int) -> None:
        import array

        from rclpy.action import ActionServer, CancelResponse, GoalResponse
        from rclpy.callback_groups import ReentrantCallbackGroup
        from test_msgs.action import Fibonacci
        self._Fibonacci = Fibonacci
        self._reject = GoalResponse.REJECT
        self._accept = GoalResponse.ACCEPT
        self.executor = executor
        self.period = period
        self.template = array.array('i', [0] * (1 + pad))
        self.lock = threading.Lock()
        self.active: dict[int, list[Any]] = {}  # id(handle) -> [handle, next k, order, done]
        self.published = 0
        self.accepted = 0
        self.late_ticks = 0
        self.running = True
        self.server = ActionServer(
            node, Fibonacci, action, execute_callback=self.execute,
            goal_callback=lambda request: self._reject if request.order < 0 else self._accept,
            cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=ReentrantCallbackGroup(), **_qos_kwargs(depth, 'pub'))
        self.ticker = threading.Thread(target=self.tick, daemon=True)
        self.ticker.start()

    def publish(self, goal_handle: Any, k: int) -> None:
        import array
        sequence = array.array('i', self.template)
        sequence[0] = k
        goal_handle.publish_feedback(self._Fibonacci.Feedback(sequence=sequence))
        with self.lock:
            self.published += 1

    async def execute(self, goal_handle: Any) -> Any:
        from rclpy.task import Future
        order = goal_handle.request.order
        if order > 0:
            self.publish(goal_handle, 0)
        done = Future()
        entry = [goal_handle, 1 if order > 0 else 0, order, done]
        with self.lock:
            self.accepted += 1
            self.active[id(goal_handle)] = entry
        outcome = await done
        if outcome == 'canceled':
            goal_handle.canceled()
        else:
            goal_handle.succeed()
        return self._Fibonacci.Result(sequence=[entry[1]])

    def tick(self) -> None:
        due = time.monotonic()
        while self.running:
            due += self.period
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -self.period:
                self.late_ticks += 1  # behind by more than a period: restart the schedule
                due = time.monotonic()
            with self.lock:
                goals = list(self.active.items())
            finished = []
            for key, entry in goals:
                goal_handle, k, order, done = entry
                if goal_handle.is_cancel_requested:
                    finished.append((key, done, 'canceled'))
                elif k >= order:
                    finished.append((key, done, 'succeeded'))
                else:
                    self.publish(goal_handle, k)
                    entry[1] = k + 1
            with self.lock:
                for key, _, _ in finished:
                    del self.active[key]
            for _, done, outcome in finished:
                done.set_result(outcome)
            if finished:
                self.executor.wake()

    def stats(self) -> dict[str, Any]:
        usage = resource.getrusage(resource.RUSAGE_SELF)
        with self.lock:
            return {'t': time.monotonic(), 'published': self.published,
                    'accepted': self.accepted, 'active': len(self.active),
                    'late_ticks': self.late_ticks, 'cpu_s': usage.ru_utime + usage.ru_stime,
                    'guard_calls': guard_report()['calls']}


def role_server(action: str, period: float, pad: int, depth: int) -> int:
    """The action server. Prints STATUS, READY, then STATS every 2 s; ends when stdin closes."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    node = Node('hazard_server')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    server = TickingServer(node, executor, action, period, pad, depth)
    report = guard_report()
    say('STATUS', report['active'], report['status'])
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    stop = threading.Event()

    def stats_loop() -> None:
        while not stop.wait(2.0):
            say('STATS', json.dumps(server.stats()))

    say('STATS', json.dumps(server.stats()))
    threading.Thread(target=stats_loop, daemon=True).start()
    say('READY')
    for line in sys.stdin:  # end of input ends the server
        if line.strip() == 'stats':
            say('STATS', json.dumps(server.stats()))
    # Stop every thread that calls into rclpy, then leave without interpreter finalization: a
    # daemon thread that re-enters Python during finalization is ended by pthread_exit, whose
    # unwinding through rclpy's C++ frames calls std::terminate (SIGABRT), which is not the hazard.
    stop.set()
    server.running = False
    server.ticker.join(2.0)
    executor.shutdown(timeout_sec=2)
    spinner.join(2.0)
    sys.stdout.flush()
    os._exit(0)


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
        if not _alive(server_pid):
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
    _rcl.set_content_filter(ptr, NEVER[0])  # the first filter recreates the reader: before use
    if not client.wait_for_server(timeout_sec=20.0):
        say('NO_SERVER')
        return 1
    time.sleep(1.0)  # let discovery carry the filtered reader to the server

    def update(i: int) -> None:
        _rcl.set_content_filter(ptr, NEVER[i % 2])
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


def run_role(argv: list[str]) -> int:
    import rclpy
    role, args = argv[0], argv[1:]
    rclpy.init()
    try:
        if role == 'server':
            return role_server(args[0], float(args[1]), int(args[2]), int(args[3]))
        if role == 'goal':
            return role_goal(args[0])
        if role == 'update':
            return role_update(args[0], int(args[1]), float(args[2]), int(args[3]))
        if role == 'destroy':
            return role_destroy(args[0], int(args[1]), int(args[2]), float(args[3]))
        if role == 'create':
            return role_create(args[0], int(args[1]), int(args[2]), float(args[3]))
        if role == 'exitproc':
            return role_exitproc(args[0], int(args[1]), float(args[2]))
        raise SystemExit(f'unknown role {role!r}')
    finally:
        try:
            rclpy.try_shutdown()
        except Exception:  # noqa: BLE001 (best effort at exit)
            pass


# ==================================================================================================
# The harness
# ==================================================================================================

class Proc:
    """A child process whose merged stdout/stderr is read line by line by a thread."""

    def __init__(self, name: str, args: list[str], env: dict[str, str],
                 cwd: Optional[str] = None, core: bool = False) -> None:
        self.name = name
        self.lines: list[str] = []
        self._closed = False
        self._changed = threading.Condition()

        def allow_core() -> None:
            resource.setrlimit(resource.RLIMIT_CORE,
                               (resource.RLIM_INFINITY, resource.RLIM_INFINITY))

        self.popen = subprocess.Popen(args, env=env, cwd=cwd, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, stdin=subprocess.PIPE,
                                      text=True, errors='replace',
                                      preexec_fn=allow_core if core else None)
        self.pid = self.popen.pid
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            with self._changed:
                self.lines.append(line.rstrip('\n'))
                self._changed.notify_all()
        with self._changed:
            self._closed = True
            self._changed.notify_all()

    def wait_for(self, prefix: str, timeout: float, after: int = 0) -> Optional[str]:
        """The first line from index ``after`` on that starts with ``prefix``, or None in time."""
        deadline = time.monotonic() + timeout
        index = after
        with self._changed:
            while True:
                while index < len(self.lines):
                    if self.lines[index].startswith(prefix):
                        return self.lines[index]
                    index += 1
                remaining = deadline - time.monotonic()
                if self._closed or remaining <= 0:
                    return None
                self._changed.wait(remaining)

    def all(self, prefix: str) -> list[str]:
        with self._changed:
            return [line for line in self.lines if line.startswith(prefix)]

    def send(self, line: str) -> None:
        try:
            assert self.popen.stdin is not None
            self.popen.stdin.write(line + '\n')
            self.popen.stdin.flush()
        except (OSError, ValueError):
            pass

    def close_stdin(self) -> None:
        try:
            if self.popen.stdin is not None:
                self.popen.stdin.close()
        except OSError:
            pass

    def wait(self, timeout: float) -> Optional[int]:
        try:
            return self.popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            return None

    def stop(self) -> Optional[int]:
        """End the process: close stdin, then SIGINT, SIGTERM, SIGKILL; return its exit status."""
        self.close_stdin()
        steps = ((lambda: None, 3.0),
                 (lambda: self.popen.send_signal(signal.SIGINT), 3.0),
                 (self.popen.terminate, 3.0), (self.popen.kill, 10.0))
        for action, grace in steps:
            if self.popen.poll() is not None:
                break
            try:
                action()
            except ProcessLookupError:
                break
            self.wait(grace)
        self._reader.join(5.0)
        return self.popen.poll()

    def tail(self, n: int = 30) -> str:
        return f'--- {self.name} (rc={self.popen.poll()}) ---\n' + '\n'.join(self.lines[-n:])


def plain_env(domain: int, **extra: str) -> dict[str, str]:
    """os.environ without the guard, with ``domain``, localhost-only discovery and Fast DDS."""
    from cft_action import guard
    env = dict(os.environ)
    try:
        ours = os.path.realpath(guard.library_path())
    except guard.GuardUnavailable:
        ours = None
    kept = [e for e in re.split(r'[\s:]+', env.get('LD_PRELOAD', ''))
            if e and os.path.realpath(e) != ours]
    if kept:
        env['LD_PRELOAD'] = ':'.join(kept)
    else:
        env.pop('LD_PRELOAD', None)
    for name in ('CFT_GUARD_DEBUG', 'CFT_ACTION_FEEDBACK_FILTER'):
        env.pop(name, None)
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               RMW_IMPLEMENTATION='rmw_fastrtps_cpp', PYTHONUNBUFFERED='1')
    env.update(extra)
    return env


def server_env(domain: int, guarded: bool) -> dict[str, str]:
    from cft_action import guard
    env = plain_env(domain)
    return guard.environment(env) if guarded else env


def signal_name(rc: Optional[int]) -> str:
    if rc is None:
        return 'running'
    if rc < 0:
        try:
            return signal.Signals(-rc).name
        except ValueError:
            return f'signal {-rc}'
    return f'exit {rc}'


def core_backtrace(directory: str, pid: int, keep: bool = False,
                   frames: int = 25) -> tuple[Optional[str], list[str]]:
    """Return (core path or None, the crashing thread's backtrace frames) for a dead server.

    The kernel's ``core_pattern`` decides the name; a relative pattern (``core``, ``core.%p``)
    puts it into the server's cwd, which is ``directory``. Deletes the core unless ``keep``.
    """
    candidates = [p for p in Path(directory).iterdir() if p.name.startswith('core')]
    if not candidates:
        return None, []
    core = max(candidates, key=lambda p: p.stat().st_mtime)
    gdb = shutil.which('gdb')
    frames_out: list[str] = []
    if gdb:
        try:
            result = subprocess.run(
                [gdb, '-batch', '-nx', '-iex', 'set auto-load off',
                 '-ex', 'set debuginfod enabled off', '-ex', f'bt {frames}',
                 os.path.realpath(PYTHON), str(core)],
                capture_output=True, text=True, timeout=180, stdin=subprocess.DEVNULL)
            seen = set()
            for line in result.stdout.splitlines():
                number = re.match(r'#(\d+)\s', line)
                if number and number.group(1) not in seen:  # gdb prints frame #0 twice
                    seen.add(number.group(1))
                    frames_out.append(re.sub(r'\s+', ' ', line.strip()))
        except subprocess.TimeoutExpired:
            frames_out = ['(gdb timed out)']
    else:
        frames_out = ['(gdb not installed: backtrace not read)']
    if not keep:
        try:
            core.unlink()
        except OSError:
            pass
    return (str(core) if keep else f'{core} (deleted)'), frames_out


def short_frame(frame: str) -> str:
    """``#3 0x.. in ns::Class::member(args) () from lib.so`` -> ``Class::member``."""
    m = re.match(r'#\d+\s+(?:0x[0-9a-f]+ in )?(.*)$', frame)
    name = m.group(1) if m else frame
    previous = None
    while previous != name:  # template arguments, innermost first
        previous, name = name, re.sub(r'<[^<>]*>', '', name)
    name = name.split('(', 1)[0].strip().split(' ')[-1]
    return '::'.join(name.split('::')[-2:]) or frame


def stats_of(line: Optional[str]) -> Optional[dict[str, Any]]:
    if not line:
        return None
    try:
        return json.loads(line.split(' ', 1)[1])
    except (IndexError, ValueError):
        return None


class Cell:
    """One cell of the matrix: event x period x payload x guard."""

    def __init__(self, event: str, period: float, payload: str, guarded: bool,
                 bound: int) -> None:
        self.event, self.period, self.payload, self.guarded = event, period, payload, guarded
        self.bound = bound

    def label(self) -> str:
        return (f'{self.event} period={self.period * 1000:g}ms payload={self.payload} '
                f'guard={"on" if self.guarded else "off"}')


def run_cell(cell: Cell, opts: argparse.Namespace) -> dict[str, Any]:
    """Run one cell and return what happened. Asserts nothing; never retries."""
    domain = random.randint(1, 101)
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

    role = [PYTHON, str(THIS), '_role']
    try:
        server = start('server', [*role, 'server', action, str(cell.period),
                                  str(PAYLOADS[cell.payload]), '0'],
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
                          'client_rc': events.popen.poll()}
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
        if server.popen.poll() is None:
            server.send('stats')
            after_line = server.wait_for('STATS', 5.0, after=len(server.lines)) or after_line
            outcome['server'] = 'alive'
        else:
            server.wait(10.0)
            outcome['server'] = signal_name(server.popen.poll())
        s0, s1 = stats_of(before), stats_of(after_line)
        if s0 and s1 and s1['t'] > s0['t']:
            outcome['feedback_per_s'] = round((s1['published'] - s0['published'])
                                              / (s1['t'] - s0['t']))
            outcome['late_ticks'] = s1['late_ticks'] - s0['late_ticks']
        if s1:
            outcome['guard_calls'] = s1.get('guard_calls')
        return outcome
    finally:
        server_dead_before_stop = started and started[0].popen.poll() is not None
        for proc in started:  # the server first, so that client exits are not counted
            proc.stop()
        if started and started[0].name == 'server':
            server = started[0]
            if not server_dead_before_stop and server.popen.poll() not in (0, None):
                outcome['server_at_stop'] = signal_name(server.popen.poll())
            if server.popen.poll() is not None and server.popen.poll() < 0:
                core, frames = core_backtrace(workdir, server.pid, keep=opts.keep_cores)
                outcome['core'] = core
                outcome['backtrace'] = frames
                if core is None:
                    outcome['backtrace_note'] = 'no core file (see core_pattern / ulimit)'
            tails = [p.tail() for p in started if p.popen.poll() not in (0, None)
                     or 'error' in outcome]
            if tails:
                outcome['logs'] = tails
        if not opts.keep_cores:
            shutil.rmtree(workdir, ignore_errors=True)
        outcome['cell_wall_s'] = round(time.monotonic() - t_cell, 1)


def run_exit_events(cell: Cell, opts: argparse.Namespace, action: str, domain: int,
                    server: Proc, started: list[Proc]) -> dict[str, Any]:
    """One process with ``k`` filtered readers after the other, each exiting normally."""
    role = [PYTHON, str(THIS), '_role']
    t0 = time.monotonic()
    for i in range(1, cell.bound + 1):
        proc = Proc(f'exit{i}', [*role, 'exitproc', action, str(opts.k), str(opts.settle)],
                    plain_env(domain))
        started.append(proc)
        ready = proc.wait_for('READY', 60.0 + 2.0 * opts.k)
        if server.popen.poll() is not None or not _alive(server.pid):
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
        if server.popen.poll() is not None or not _alive(server.pid):
            return {'survived': False, 'events': i, 'seconds': round(time.monotonic() - t0, 2)}
    return {'survived': True, 'events': cell.bound, 'seconds': round(time.monotonic() - t0, 2)}


def describe(outcome: dict[str, Any]) -> str:
    if 'error' in outcome:
        return f'inconclusive: {outcome["error"]}'
    if outcome.get('survived'):
        return f'survived {outcome["events"]}'
    during = f', during {outcome["during"]}' if outcome.get('during') else ''
    return f'crashed after {outcome["events"]} ({outcome.get("server", "?")}{during})'


def crash_site(outcome: dict[str, Any]) -> str:
    """The first Fast DDS frames of a backtrace, shortened, or the reason there is none."""
    frames = outcome.get('backtrace') or []
    if not frames:
        return outcome.get('backtrace_note', '')
    interesting = [short_frame(f) for f in frames if 'eprosima' in f]
    return ' < '.join((interesting or [short_frame(f) for f in frames])[:4])


def markdown_table(results: list[dict[str, Any]]) -> str:
    rows = ['| event | feedback period | payload | guard | bound | result | feedback/s '
            '| server crash site (innermost Fast DDS frames) |',
            '|---|---|---|---|---|---|---|---|']
    for r in results:
        event = r['event'] + (f' (k={r["k"]})' if r.get('k') else '')
        rows.append(f'| {event} | {r["period_ms"]:g} ms | {r["payload"]} | '
                    f'{"on" if r["guard"] else "off"} | {r["bound"]} | {describe(r)} | '
                    f'{r.get("feedback_per_s", "")} | {crash_site(r)} |')
    return '\n'.join(rows)


def machine_line() -> str:
    from importlib import metadata
    cpu = platform.processor() or platform.machine()
    try:
        with open('/proc/cpuinfo') as f:
            cpu = next(line.split(':', 1)[1].strip() for line in f if line.startswith('model name'))
    except (OSError, StopIteration):
        pass
    versions = []
    for dist in ('ros-jazzy-rclpy', 'ros-fastrtps', 'ros-rmw-fastrtps-cpp'):
        try:
            versions.append(f'{dist} {metadata.version(dist)}')
        except metadata.PackageNotFoundError:
            pass
    return (f'{platform.node()}: {os.cpu_count()} CPUs ({cpu}), Linux {platform.release()}, '
            f'Python {platform.python_version()}, {", ".join(versions)}; '
            f'load average {os.getloadavg()[0]:.2f} at start')


def main(argv: Optional[list[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == '_role':
        return run_role(argv[1:])
    parser = argparse.ArgumentParser(
        description=__doc__.split('\n\n')[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='Every cell: a fresh server, goal client and event client; cells never retried.')
    parser.add_argument('--events', nargs='+', choices=EVENTS, default=list(EVENTS))
    parser.add_argument('--periods', nargs='+', type=float, default=[0.0005, 0.01, 0.1],
                        metavar='S', help='server feedback periods in seconds')
    parser.add_argument('--payloads', nargs='+', choices=list(PAYLOADS),
                        default=list(PAYLOADS))
    parser.add_argument('--guard', nargs='+', choices=['on', 'off'], default=['on', 'off'])
    parser.add_argument('--updates', type=int, default=300, help='bound of filter updates')
    parser.add_argument('--interval', type=float, default=0.02,
                        help='seconds between filter updates')
    parser.add_argument('--destroys', type=int, default=30, help='bound of destroyed readers')
    parser.add_argument('--creates', type=int, default=30, help='bound of created readers')
    parser.add_argument('--exits', type=int, default=10, help='bound of exiting processes')
    parser.add_argument('--k', type=int, default=10,
                        help='filtered readers in each exiting process')
    parser.add_argument('--settle', type=float, default=0.3,
                        help='seconds for discovery after each create or destroy')
    parser.add_argument('--reps', type=int, default=1, help='runs of each cell')
    parser.add_argument('--keep-cores', action='store_true',
                        help='keep core files and work directories (printed)')
    parser.add_argument('--json', metavar='PATH', help='also write the results as JSON')
    parser.add_argument('--list', action='store_true', help='only list the selected cells')
    opts = parser.parse_args(argv)

    bounds = {'update': opts.updates, 'destroy': opts.destroys, 'create': opts.creates,
              'exit': opts.exits}
    cells = [Cell(event, period, payload, g == 'on', bounds[event])
             for event in opts.events for period in opts.periods
             for payload in opts.payloads for g in opts.guard for _ in range(opts.reps)]
    if opts.list:
        for cell in cells:
            print(cell.label(), 'bound', cell.bound)
        return 0
    started_at = datetime.datetime.now(datetime.timezone.utc)
    header = {'date_utc': started_at.strftime('%Y-%m-%d %H:%M'), 'machine': machine_line(),
              'command': 'python benchmarks/hazard.py ' + ' '.join(argv),
              'gdb': shutil.which('gdb') is not None,
              'core_pattern': Path('/proc/sys/kernel/core_pattern').read_text().strip()
              if Path('/proc/sys/kernel/core_pattern').exists() else None}
    print(json.dumps(header), flush=True)
    results = []
    for n, cell in enumerate(cells, 1):
        print(f'[{n}/{len(cells)}] {cell.label()} bound {cell.bound} ...', flush=True)
        outcome = run_cell(cell, opts)
        results.append(outcome)
        print(f'    -> {describe(outcome)}; server {outcome.get("server", "?")}; '
              f'{outcome.get("feedback_per_s", "?")} feedback/s; '
              f'{outcome.get("cell_wall_s")} s', flush=True)
        if outcome.get('backtrace'):
            print('    backtrace:\n      ' + '\n      '.join(outcome['backtrace'][:12]),
                  flush=True)
        if 'error' in outcome:
            for tail in outcome.get('logs', []):
                print('    ' + tail.replace('\n', '\n    '), flush=True)
    print()
    print(markdown_table(results))
    if opts.json:
        Path(opts.json).write_text(json.dumps({'header': header, 'results': results}, indent=1))
        print(f'\nresults written to {opts.json}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
