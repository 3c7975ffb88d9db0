"""Does the server have the client's feedback reader when it takes the client's first goal?

A client is created, waits for the server (``wait_for_server``), completes one order-0 goal, then
sends one goal with a feedback callback; the server (:mod:`harness.server`, unguarded, a new one
for each client) records which feedback readers its graph showed when it took that goal. A goal
taken while the graph lacks the client's reader has its first feedback published to nobody.
Configurations alternate, life by life: plain rclpy, ``client`` and ``goals`` mode. Also timed:
``wait_for_server``, which in the library waits for the proof that the server has the reader::

    python -m benchmarks.first_goal_reader --lives 300

Results go to ``benchmarks/results/first-goal-reader-<date>-<host>.json``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import statistics
import time
import uuid
from pathlib import Path
from typing import Any

from harness.domain import unused_domain

os.environ.setdefault('ROS_DOMAIN_ID', str(unused_domain()))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from rclpy.action import ActionClient as PlainActionClient
from test_msgs.action import Fibonacci

from cft_action import ActionClient
from harness.machine import environment_facts
from harness.proc import Proc, python_module
from harness.ros import RosSession
from harness.server import feedback_reader_gids

REPO = Path(__file__).resolve().parent.parent
CONFIGS = ('rclpy', 'client', 'goals')


def one_life(config: str, period: float) -> dict[str, Any]:
    """One client against a new server: whether the server knew its reader at its first goal."""
    action = f'/first_goal_reader_{uuid.uuid4().hex[:10]}'
    server = Proc('server', python_module('harness.server', action, period, '--depth', 'all',
                                          '--record-readers'), dict(os.environ))
    ros = RosSession()
    life: dict[str, Any] = {'config': config}
    try:
        server.expect('READY', 30)
        client = (PlainActionClient(ros.node, Fibonacci, action) if config == 'rclpy' else
                  ActionClient(ros.node, Fibonacci, action, feedback_filter=config))
        t0 = time.monotonic()
        life['ready'] = client.wait_for_server(timeout_sec=20)
        life['wait_for_server_ms'] = round((time.monotonic() - t0) * 1000, 1)
        answered = False
        for _ in range(10):  # the order-0 round trip, resent as the soak's probe is
            probe = client.send_goal_async(Fibonacci.Goal(order=0))
            if ros.spin_until(probe.done, 2):
                answered = True
                break
        life['round_trip'] = answered
        goal = client.send_goal_async(Fibonacci.Goal(order=1), feedback_callback=lambda _: None)
        if not (answered and ros.spin_until(goal.done, 20)):
            life['failed'] = 'no goal response'
            return life
        goal_uuid = bytes(goal.result().goal_id.uuid).hex()
        own = set(feedback_reader_gids(ros.node, f'{action}/_action/feedback',
                                       ros.node.get_name()))
        readers = json.loads(server.request('readers', 'READERS', 10).split(' ', 1)[1])
        life['reader_known'] = bool(own & set(readers.get(goal_uuid, [])))
        if config != 'rclpy':
            life['held_goals'] = client.feedback_filter_state.held_goals
        client.destroy()
        return life
    finally:
        ros.close()
        server.stop()


def summary(lives: list[dict[str, Any]], config: str) -> dict[str, Any]:
    mine = [life for life in lives if life['config'] == config]
    measured = [life for life in mine if 'reader_known' in life]
    waits = sorted(life['wait_for_server_ms'] for life in mine if 'wait_for_server_ms' in life)
    return {'config': config, 'lives': len(mine), 'measured': len(measured),
            'reader_unknown': sum(not life['reader_known'] for life in measured),
            'failed': len(mine) - len(measured),
            'held_first_goals': sum(life.get('held_goals', 0) for life in measured),
            'wait_for_server_ms_p50': round(statistics.median(waits), 1) if waits else None,
            'wait_for_server_ms_p95': waits[math.ceil(0.95 * len(waits)) - 1] if waits else None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--lives', type=int, default=300, help='client lives in all')
    parser.add_argument('--period', type=float, default=0.01, help='feedback period, s')
    parser.add_argument('--configs', default=','.join(CONFIGS))
    args = parser.parse_args()
    configs = args.configs.split(',')
    started = datetime.datetime.now(datetime.timezone.utc)
    header = {'date_utc': f'{started:%Y-%m-%d %H:%M}', 'machine': environment_facts(),
              'command': 'python -m benchmarks.first_goal_reader ' + ' '.join(
                  f'--{k} {v}' for k, v in vars(args).items()),
              'load_average_at_start': os.getloadavg()}
    print(json.dumps({k: header[k] for k in ('date_utc', 'command')}), flush=True)
    lives = []
    for n in range(args.lives):
        lives.append(one_life(configs[n % len(configs)], args.period))
        if (n + 1) % 30 == 0 or n + 1 == args.lives:
            unknown = {c: summary(lives, c)['reader_unknown'] for c in configs}
            print(f'  {n + 1}/{args.lives} lives; reader unknown at the first goal: {unknown}',
                  flush=True)
    rows = [summary(lives, config) for config in configs]
    plain = next((row for row in rows if row['config'] == 'rclpy'), None)
    print(f'\n{"config":<8} {"lives":>6} {"reader unknown":>15} {"failed":>7} {"held":>5} '
          f'{"wait_for_server ms p50 / p95":>29} {"p50 - rclpy":>12}')
    for row in rows:
        # A difference, not a ratio: plain rclpy's wait is often 0 ms (the server was seen at once).
        extra = (f'{row["wait_for_server_ms_p50"] - plain["wait_for_server_ms_p50"]:+.1f} ms'
                 if plain and plain['wait_for_server_ms_p50'] is not None
                 and row['wait_for_server_ms_p50'] is not None else '-')
        print(f'{row["config"]:<8} {row["measured"]:>6} {row["reader_unknown"]:>15} '
              f'{row["failed"]:>7} {row["held_first_goals"]:>5} '
              f'{row["wait_for_server_ms_p50"]:>14.1f} / {row["wait_for_server_ms_p95"]:<12.1f} '
              f'{extra:>12}')
    out = REPO / 'benchmarks' / 'results' / \
        f'first-goal-reader-{started:%Y-%m-%d}-{platform.node()}.json'
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({**header, 'load_average_at_end': os.getloadavg(), 'rows': rows,
                               'lives': lives}, indent=1))
    print(f'\nresults: {out}')


if __name__ == '__main__':
    main()
