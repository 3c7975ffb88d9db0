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

The server (``demos/_server.py``, rclpy's default queues) publishes feedback every PERIOD s
(``--periods``, default 0.0005 0.01 0.1) from a ticker thread to one goal that an ordinary,
unfiltered client keeps running; the feedback ``sequence`` is ``small`` (the server's 3-int32
header, 12 bytes) or ``10k`` (2500 int32, 10,000 bytes) (``--payloads``). Each cell runs
to the first server crash or to its bound of events, with the guard ``on`` and ``off``
(``--guard``). A crashed server's core (``ulimit -c unlimited`` in the server, cwd a fresh
directory) is read with gdb for the crashing thread's backtrace; without gdb or a core, the exit
signal is all that is recorded. A crash is evidence: cells are never retried.

Each cell has a ROS domain of its own (random, 1..101), localhost-only discovery and a unique action
name. Every wait is bounded; every process started is stopped by this script, by its pid.

Examples::

    python benchmarks/hazard.py --events update --periods 0.0005 --payloads small --updates 50
    python benchmarks/hazard.py --events update destroy --periods 0.0005 0.01 --payloads small \\
        --updates 200 --destroys 30 --json hazard.json

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

from demos._proc import Proc, run_role  # noqa: E402
from demos._server import HEADER  # noqa: E402

THIS = Path(__file__).resolve()
PYTHON = sys.executable
SERVER = ROOT / 'demos' / '_server.py'

EVENTS = ('update', 'destroy', 'create', 'exit')
# int32 elements after the server's 3-element header (index, publish time): 3 or 2500 in all
PAYLOADS = {'small': 0, '10k': 2500 - HEADER}
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


#: The child processes of this script: ``hazard.py _role NAME ARGS...``.
ROLES = {'goal': role_goal, 'update': role_update, 'destroy': role_destroy,
         'create': role_create, 'exitproc': role_exitproc}


# ==================================================================================================
# The harness
# ==================================================================================================

def server_command(action: str, period: float, pad: int, depth: Optional[int] = None) -> list[str]:
    """The action server (``demos/_server.py``) with counters every 2 s, for a crash watcher.

    Without ``depth``, its queues have rclpy's defaults, as an ordinary server's.
    """
    depth_args = [] if depth is None else ['--depth', str(depth)]
    return [PYTHON, str(SERVER), action, str(period), '--pad', str(pad), *depth_args,
            '--stats-every', '2']


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


def run_cell(cell: Cell, opts: argparse.Namespace, domain: Optional[int] = None) -> dict[str, Any]:
    """Run one cell and return what happened. Asserts nothing; never retries.

    ``opts`` needs ``interval``, ``settle``, ``k`` and ``keep_cores``; ``domain`` is random
    (1..101) unless given.
    """
    domain = domain or random.randint(1, 101)
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
            if server.poll() is not None and server.poll() < 0:
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
    role = [PYTHON, str(THIS), '_role']
    t0 = time.monotonic()
    for i in range(1, cell.bound + 1):
        proc = Proc(f'exit{i}', [*role, 'exitproc', action, str(opts.k), str(opts.settle)],
                    plain_env(domain))
        started.append(proc)
        ready = proc.wait_for('READY', 60.0 + 2.0 * opts.k)
        if server.poll() is not None or not _alive(server.pid):
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
        if server.poll() is not None or not _alive(server.pid):
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
        return run_role(argv[1:], ROLES)
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
