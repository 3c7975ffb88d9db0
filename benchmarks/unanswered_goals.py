# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Goals that are never answered: a burst of goals right after ``wait_for_server()``.

Usage: ``python -m benchmarks.unanswered_goals [--runs N] [--configs rclpy,client]
[--depth default|1000] [--server-depth N] [--clients 3] [--goals 8] [--spin thread|inline]
[--out FILE] [--summarize JSON...]``

Per run, one guarded server (``cft-action guard -- python -m harness.server --executor multi``,
feedback every 20 ms) starts, then ``--clients`` client processes at once. Each creates its action
client, waits for the server, and sends ``--goals`` goals at once: the first with a caller-supplied
uuid4 (in ``client`` mode it needs a filter update, so the library holds it and every later goal
until the proof of arrival), the second without a feedback callback, the rest plain. With
``--spin thread`` (default) an executor spins in a thread of its own from the start and the main
thread sends, as a script does; with ``--spin inline`` the main thread sends, then spins.

Each client waits up to ``--response-timeout`` seconds for its goal responses, and reports per goal
whether one came, and how many goal responses its action client took from rcl and ignored (rclpy
ignores a response whose sequence number it does not know yet). The server reports, per goal UUID,
whether it took the request and sent the response, or failed to send it (``harness.server``'s
``requests`` command). An unanswered goal is thus:

- ``not taken``: the server never took its request (it was not sent, or lost on the way in);
- ``send failed``: rmw refused to send the response (the response writer had not matched the
  client's response reader within its wait: "client will not receive response");
- ``sent, not received``: sent, but the client's action client never saw it;
- ``taken, not answered``: the server still works on it.

``--server-depth`` gives the server's goal service another depth than the clients' (a control that
tells the server's request reader from the clients' queues). The server also reports the order and
time (``time.monotonic()``, system-wide) in which it took the requests, and each client the time
of each ``send_goal_async`` call (a held ``client``-mode request leaves later).

Configurations alternate within each run index. Every process has ``ROS_DOMAIN_ID`` ``--domain``
(97) and localhost-only discovery; every wait is bounded and every process is stopped.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from typing import Any, Optional

from harness.crash import machine_line, plain_env
from harness.machine import environment_facts
from harness.proc import Proc, guard_command, main_or_role, python_module
from harness.report import say

#: Feedback period of the server, s.
PERIOD_S = 0.02
#: Feedback messages per goal.
ORDER = 10


# ==================================================================================================
# The client process
# ==================================================================================================

def make_counting_client(node: Any, config: str, action: str, depth: str) -> Any:
    """The action client of ``config``, which counts the goal responses it takes and ignores."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from test_msgs.action import Fibonacci
    if config == 'rclpy':
        from rclpy.action import ActionClient as base
        kwargs: dict[str, Any] = {}
    else:
        from cft_action import ActionClient as base
        kwargs = {'feedback_filter': config}
    if depth != 'default':
        kwargs['goal_service_qos_profile'] = QoSProfile(
            depth=int(depth), reliability=ReliabilityPolicy.RELIABLE)

    class Counting(base):  # type: ignore[misc, valid-type]
        def __init__(self, *args: Any, **kw: Any) -> None:
            self.responses_taken = 0
            self.responses_ignored = 0
            self.responses_foreign = 0
            super().__init__(*args, **kw)

        def take_data(self) -> dict:
            ready = self._is_goal_response_ready
            data = super().take_data()
            if 'goal' in data:
                self.responses_taken += 1
            elif ready:
                # rmw took a response for another client from the shared response topic and
                # dropped it (rmw_fastrtps' __rmw_take_response compares the related GUID).
                self.responses_foreign += 1
            return data

        async def execute(self, taken_data: dict) -> None:
            if ('goal' in taken_data
                    and taken_data['goal'][0] not in self._goal_sequence_number_to_goal_id):
                self.responses_ignored += 1
            await super().execute(taken_data)

    return Counting(node, Fibonacci, action, **kwargs)


def role_client(action: str, config: str, goals: int, depth: str, spin: str,
                timeout: float) -> int:
    """Send the burst of goals and report which got a response."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from test_msgs.action import Fibonacci
    from unique_identifier_msgs.msg import UUID

    node = Node(f'unanswered_{uuid.uuid4().hex[:8]}')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    client = make_counting_client(node, config, action, depth)
    spinner = None
    if spin == 'thread':
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
    t0 = time.monotonic()
    if not client.wait_for_server(timeout_sec=30):
        print('NO SERVER', flush=True)
        return 1
    waited = time.monotonic() - t0
    records: list[dict[str, Any]] = []
    lock = threading.Lock()
    sent_at = time.monotonic()

    def on_response(record: dict[str, Any]) -> Any:
        def done(future: Any) -> None:
            with lock:
                record['response_s'] = round(time.monotonic() - sent_at, 4)
                record['accepted'] = bool(future.result().accepted)
        return done

    for i in range(goals):
        goal_uuid = UUID(uuid=list(uuid.uuid4().bytes)) if i == 0 else None
        callback = None if i == 1 else (lambda _msg: None)
        future = client.send_goal_async(Fibonacci.Goal(order=ORDER), callback, goal_uuid=goal_uuid)
        record = {'i': i, 'explicit_uuid': i == 0, 'callback': callback is not None,
                  'called_t': time.monotonic(), 'future': future}
        records.append(record)
        future.add_done_callback(on_response(record))
    deadline = time.monotonic() + timeout
    # Wait for the done callbacks, not the futures: a future's callbacks run as executor tasks,
    # which an inline loop that stopped at the last done future would never spin.
    while time.monotonic() < deadline and not all('response_s' in r for r in records):
        if spinner is None:
            executor.spin_once(timeout_sec=0.05)
        else:
            time.sleep(0.05)
    state = getattr(client, 'feedback_filter_state', None)
    report = {
        'wait_for_server_s': round(waited, 3),
        'responses_taken': client.responses_taken, 'responses_ignored': client.responses_ignored,
        'responses_foreign': client.responses_foreign,
        'held_goals': state.held_goals if state else 0,
        'arrival_timeouts': state.arrival_timeouts if state else 0,
        'updates': state.updates if state else 0,
        'goals': [{**{k: v for k, v in r.items() if k != 'future'},
                   # The UUID the request carried: rclpy and cft set it on the request.
                   'uuid': _goal_uuid_of(client, r['future'])} for r in records]}
    print('RESULT ' + json.dumps(report), flush=True)
    # Stay until told to go, so that a stuck client can be inspected (gdb -p).
    sys.stdin.readline()
    executor.shutdown(timeout_sec=2)
    if spinner is not None:
        # A daemon spinner still inside rclpy when the interpreter finalizes aborts the process
        # (std::terminate): it ends first.
        spinner.join(timeout=5)
    return 0


def _goal_uuid_of(client: Any, future: Any) -> Optional[str]:
    """The UUID of a goal's request, from the client's bookkeeping."""
    if future.done():
        return bytes(future.result().goal_id.uuid).hex()
    for sequence_number, pending in list(client._pending_goal_requests.items()):
        if pending is future or _forwards_to(pending, future):
            goal_id = client._goal_sequence_number_to_goal_id.get(sequence_number)
            return None if goal_id is None else bytes(goal_id.uuid).hex()
    held_goals = getattr(client, '_held_goals', None)  # cft_action's, not plain rclpy's
    for held in held_goals.waiting if held_goals is not None else ():
        if held.future is future:
            return 'held:' + bytes(held.goal_uuid.uuid).hex()
    return None


def _forwards_to(source: Any, target: Any) -> bool:
    """Whether ``source`` is a cft held goal's sent future, forwarded to ``target``."""
    for callback in getattr(source, '_callbacks', []):
        closure = getattr(callback, '__closure__', None) or ()
        if any(cell.cell_contents is target for cell in closure
               if _cell_filled(cell)):
            return True
    return False


def _cell_filled(cell: Any) -> bool:
    try:
        _ = cell.cell_contents
    except ValueError:
        return False
    return True


ROLES = {'client': role_client}


# ==================================================================================================
# The orchestrator
# ==================================================================================================

def one_run(opts: argparse.Namespace, config: str, env: dict[str, str]) -> dict[str, Any]:
    """One server, ``opts.clients`` clients at once; what each goal got."""
    action = f'/cft_unanswered_{uuid.uuid4().hex[:8]}'
    server_args = ['--executor', 'multi']
    server_depth = opts.server_depth or opts.depth
    if server_depth != 'default':
        server_args += ['--goal-depth', server_depth]
    server = Proc('server', [*guard_command(), *python_module(
        'harness.server', action, PERIOD_S, *server_args)], env,
        cwd=tempfile.mkdtemp(prefix='cft_unanswered_'), core=True)
    clients: list[Proc] = []
    run: dict[str, Any] = {'config': config}
    try:
        if server.wait_for('READY', 60.0) is None:
            run['error'] = 'server not ready\n' + server.tail()
            return run
        status = server.last('STATUS') or ''
        run['guard'] = status.split(' ', 2)[2] if status.count(' ') >= 2 else status
        clients = [Proc(f'{config} client {c}', python_module(
            'benchmarks.unanswered_goals', '_role', 'client', action, config, opts.goals,
            opts.depth, opts.spin, opts.response_timeout), env) for c in range(opts.clients)]
        reports = []
        for proc in clients:
            line = proc.wait_for('RESULT', opts.response_timeout + 60.0)
            reports.append(json.loads(line.split(' ', 1)[1]) if line else
                           {'error': 'no RESULT\n' + proc.tail(10)})
        stuck = [proc.pid for proc, rep in zip(clients, reports)
                 if any('response_s' not in g for g in rep.get('goals', []))]
        if stuck and opts.gdb:
            run['backtraces'] = {str(pid): backtrace(pid) for pid in stuck[:1]}
        requests = server.request_json('requests', 'REQUESTS', 30.0)
        stats = server.request_json('stats', 'STATS', 30.0)
        run['takes'] = server.request_json('takes', 'TAKES', 30.0)
        run['server'] = {k: stats.get(k) for k in (
            'goal_requests', 'goal_responses', 'goal_response_errors', 'accepted', 'published')}
        run['server']['alive'] = server.poll() is None
        run['server']['warnings'] = [
            ln for ln in server.lines if 'WARN' in ln or 'ERROR' in ln][:20]
        for proc, rep in zip(clients, reports):
            rep['warnings'] = [ln for ln in proc.lines if 'WARN' in ln or 'ERROR' in ln][:20]
            for goal in rep.get('goals', []):
                key = (goal.get('uuid') or '').removeprefix('held:')
                goal['server'] = requests.get(key, 'not taken') if key else 'unknown'
        run['clients'] = reports
    finally:
        for proc in clients:
            proc.stop(grace=2.0)
        server.stop(grace=2.0)
    return run


def backtrace(pid: int) -> str:
    """Every thread's stack of a stuck client, by gdb (empty if gdb is missing)."""
    import shutil
    import subprocess
    if not shutil.which('gdb'):
        return ''
    try:
        out = subprocess.run(['gdb', '-p', str(pid), '-batch', '-ex', 'thread apply all bt'],
                             capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        return 'gdb timed out'
    return out.stdout[-20000:]


def classify(goal: dict[str, Any]) -> str:
    """What happened to a goal without a response."""
    return {'not taken': 'not taken', 'failed': 'send failed', 'sent': 'sent, not received',
            'taken': 'taken, not answered'}.get(goal.get('server', ''), goal.get('server', '?'))


def pattern(goal: dict[str, Any], goals: list[dict[str, Any]]) -> str:
    """Where an unanswered goal sits among its client's goals, by what the server took.

    ``gap``: a later goal of the same client was taken, so the request writer and the server's
    request reader had matched before it: only an overflow loses it then. ``prefix``: no earlier
    goal of the client was taken but a later one was. ``all``: none of the client's goals was
    taken. ``tail``: an earlier one was taken, no later one.
    """
    taken = [g['server'] != 'not taken' for g in goals]
    i = goal['i']
    before, after = any(taken[:i]), any(taken[i + 1:])
    if after:
        return 'gap' if before else 'prefix'
    return 'tail' if before else 'all'


def summarize(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Per configuration: runs, runs with an unanswered goal, clients and goals, by cause."""
    out: dict[str, Any] = {}
    for run in runs:
        s = out.setdefault(run['config'], {'runs': 0, 'runs_with_unanswered': 0, 'errors': 0,
                                           'clients_with_unanswered': 0,
                                           'clients_all_unanswered': 0, 'goals': 0,
                                           'unanswered': 0, 'causes': {},
                                           'responses_ignored': 0, 'send_errors': 0,
                                           'server_requests_short': 0, 'patterns': {}})
        s['runs'] += 1
        if 'error' in run or any('error' in c for c in run.get('clients', [])):
            s['errors'] += 1
        any_missing = False
        for client in run.get('clients', []):
            goals = client.get('goals', [])
            missing = [g for g in goals if 'response_s' not in g]
            s['goals'] += len(goals)
            s['unanswered'] += len(missing)
            s['responses_ignored'] += client.get('responses_ignored', 0)
            if missing:
                any_missing = True
                s['clients_with_unanswered'] += 1
                s['clients_all_unanswered'] += len(missing) == len(goals)
            for goal in missing:
                cause = classify(goal)
                s['causes'][cause] = s['causes'].get(cause, 0) + 1
                shape = pattern(goal, goals)
                s['patterns'][shape] = s['patterns'].get(shape, 0) + 1
        server = run.get('server', {})
        s['send_errors'] += server.get('goal_response_errors') or 0
        expected = sum(len(c.get('goals', [])) for c in run.get('clients', []))
        s['server_requests_short'] += max(0, expected - (server.get('goal_requests') or 0))
        s['runs_with_unanswered'] += any_missing
    return out


def fisher_two_sided(a: int, b: int, c: int, d: int) -> float:
    """Two-sided Fisher exact p for the 2x2 table [[a, b], [c, d]]."""
    from math import comb
    row1, col1, n = a + b, a + c, a + b + c + d

    def p(x: int) -> float:
        return comb(col1, x) * comb(n - col1, row1 - x) / comb(n, row1)
    observed = p(a)
    low, high = max(0, row1 + col1 - n), min(row1, col1)
    return min(1.0, sum(p(x) for x in range(low, high + 1) if p(x) <= observed * (1 + 1e-9)))


def with_fisher(summary: dict[str, Any]) -> dict[str, Any]:
    """The summary, with Fisher's exact test on runs with an unanswered goal if two configs."""
    if len(summary) == 2:
        (x, sx), (y, sy) = summary.items()
        summary['fisher_runs_with_unanswered'] = {
            'configs': [x, y], 'p_two_sided': fisher_two_sided(
                sx['runs_with_unanswered'], sx['runs'] - sx['runs_with_unanswered'],
                sy['runs_with_unanswered'], sy['runs'] - sy['runs_with_unanswered'])}
    return summary


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=30, help='runs per configuration')
    parser.add_argument('--configs', default='rclpy,client', help='rclpy, client, goals')
    parser.add_argument('--depth', default='default',
                        help="the goal service's depth, both sides: 'default' (keep-last 10) or N")
    parser.add_argument('--server-depth',
                        help="the server's goal service depth, if not --depth's (a split control)")
    parser.add_argument('--clients', type=int, default=3)
    parser.add_argument('--goals', type=int, default=8, help='goals per client')
    parser.add_argument('--spin', choices=['thread', 'inline'], default='thread')
    parser.add_argument('--response-timeout', type=float, default=10.0,
                        help='seconds a client waits for its goal responses')
    parser.add_argument('--domain', type=int, default=97, help='ROS_DOMAIN_ID of every process')
    parser.add_argument('--gdb', action='store_true', help='backtrace the first stuck client')
    parser.add_argument('--out', help='write the JSON here')
    parser.add_argument('--summarize', nargs='+', metavar='JSON',
                        help='run nothing: summarize the runs of these result files together')
    return parser.parse_args(argv)


def main(argv: list[str]) -> int:
    """Run the benchmark with the command line ``argv``."""
    opts = parse_args(argv)
    if opts.summarize:
        runs = [run for path in opts.summarize
                for run in json.loads(Path(path).read_text())['runs']]
        say(json.dumps(with_fisher(summarize(runs)), indent=1))
        return 0
    configs = opts.configs.split(',')
    env = plain_env(opts.domain)
    header = {'date_utc': datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M'),
              'machine': machine_line(), 'environment': environment_facts(),
              'command': 'python -m benchmarks.unanswered_goals ' + ' '.join(argv),
              'options': vars(opts)}
    say(json.dumps({k: header[k] for k in ('date_utc', 'machine', 'command')}))
    runs: list[dict[str, Any]] = []
    for n in range(opts.runs):
        for config in configs:
            run = one_run(opts, config, env)
            run['n'] = n
            runs.append(run)
            missing = [(c, g['i'], classify(g)) for c, client in enumerate(run.get('clients', []))
                       for g in client.get('goals', []) if 'response_s' not in g]
            say(f'run {n} {config}: {run.get("server", {})} unanswered: {missing or "none"}'
                + (f' ERROR {run["error"][:300]}' if 'error' in run else ''))
    summary = with_fisher(summarize(runs))
    header['finished_utc'] = datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M')
    result = {'header': header, 'summary': summary, 'runs': runs}
    if opts.out:
        Path(opts.out).parent.mkdir(parents=True, exist_ok=True)
        Path(opts.out).write_text(json.dumps(result, indent=1, default=str))
        say(f'wrote {opts.out}')
    say(json.dumps(summary, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main_or_role(main, ROLES))
