"""Does feedback published in the first line of ``execute`` arrive? One client, several designs.

A server that reports progress at once publishes its first feedback before the client has even
received the goal response. A filter that learns of a goal only on acceptance (the upstream design)
filters that feedback out; one that knows the goal before the request is sent does not, as long as
the filter change reaches the server's writer before the goal request does.

For each configuration (``client``, ``goals``, ``upstream``, ``rclpy``), one client sends GOALS
goals of ORDER feedback messages to a guarded server (:mod:`harness.server`), either one after
another or all at once, and counts the goals whose first feedback, and whose every feedback,
arrived, and how long each goal took from ``send_goal_async`` to its goal response (``accept_ms``)::

    python -m benchmarks.first_feedback --goals 200 --order 3

``--uuids caller`` sends every goal with a caller-supplied random ``goal_uuid``, which the filter
of a ``client``-mode client does not match yet: each costs a filter update, and a request that is
held until the update has reached the server.

Results go to ``benchmarks/results/first-feedback-<date>-<host>-<uuids>.json``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import random
import time
import uuid
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from test_msgs.action import Fibonacci
from unique_identifier_msgs.msg import UUID

from cft_action import guard
from harness import client as load_client
from harness import load
from harness.domain import unused_domain
from harness.machine import environment_facts
from harness.proc import Proc, python_module

REPO = Path(__file__).resolve().parent.parent

CONFIGS = ('client', 'goals', 'upstream', 'rclpy')
QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000,
                 reliability=ReliabilityPolicy.RELIABLE)


def spin_until(executor: SingleThreadedExecutor, done, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)
    return done()


def run_config(config: str, action: str, goals: int, order: int, burst: bool,
               caller_uuids: bool) -> dict[str, Any]:
    """One client of ``config`` sends the goals and reports what arrived."""
    node = Node(f'first_feedback_{config}')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    client = load_client.make_client(node, config, action, QOS)
    try:
        if not load_client.probe(node, executor, client, 20):
            raise SystemExit(f'{config}: the server did not answer')
        received: dict[int, list[int]] = {}
        results = []
        accept_ms: list[float] = []

        def send(index: int) -> None:
            received[index] = []
            goal_uuid = UUID(uuid=list(uuid.uuid4().bytes)) if caller_uuids else None
            sent_at = time.monotonic()

            def on_response(future) -> None:
                accept_ms.append((time.monotonic() - sent_at) * 1000)
                results.append(future.result().get_result_async())

            future = client.send_goal_async(
                Fibonacci.Goal(order=order), goal_uuid=goal_uuid,
                feedback_callback=lambda m: received[index].append(m.feedback.sequence[0]))
            future.add_done_callback(on_response)

        for index in range(goals):
            send(index)
            if not burst:
                spin_until(executor,
                           lambda index=index: len(results) > index and results[index].done(), 20)
        spin_until(executor, lambda: len(results) == goals and all(r.done() for r in results), 60)
        spin_until(executor, lambda: False, 1.0)  # stragglers
        counters = load_client.filter_counters(client)
        return {
            'config': config, 'goals': goals, 'order': order, 'burst': burst,
            'caller_uuids': caller_uuids,
            'accept_ms_p50': load.percentile(accept_ms, 0.5),
            'accept_ms_p95': load.percentile(accept_ms, 0.95),
            'accept_ms_max': max(accept_ms, default=None),
            'first_arrived': sum(1 for ks in received.values() if 0 in ks),
            'complete': sum(1 for ks in received.values() if sorted(ks) == list(range(order))),
            'filter_events': counters['updates'],
            'counters': counters,
        }
    finally:
        client.destroy()
        executor.shutdown(timeout_sec=2)
        node.destroy_node()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--goals', type=int, default=200)
    parser.add_argument('--order', type=int, default=3, help='feedback messages per goal')
    parser.add_argument('--period', type=float, default=0.01, help='feedback period, s')
    parser.add_argument('--configs', default=','.join(CONFIGS))
    parser.add_argument('--uuids', choices=('generated', 'caller'), default='generated',
                        help="who chooses the goal UUIDs: the client, or the caller (goal_uuid=)")
    args = parser.parse_args()
    os.environ.setdefault('ROS_DOMAIN_ID', str(unused_domain()))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    rclpy.init()
    action = f'/first_feedback_{random.randrange(1 << 32):08x}'
    server = Proc('server', python_module('harness.server', action, args.period, '--depth', 1000),
                  guard.environment())
    rows = []
    try:
        server.expect('READY', 30)
        for burst in (False, True):
            for config in args.configs.split(','):
                print(f'{config} {"burst" if burst else "one at a time"} ...', flush=True)
                rows.append(run_config(config, action, args.goals, args.order, burst,
                                       args.uuids == 'caller'))
    finally:
        server.stop()
        rclpy.shutdown()
    print(f'\n{args.goals} goals, {args.order} feedback each, the first in the first line of '
          f'execute, {args.period * 1000:.0f} ms apart; UUIDs {args.uuids}')
    print(f'{"config":<10} {"sending":<14} {"first arrived":>14} {"complete":>9} '
          f'{"filter events":>14} {"accept ms p50 / p95 / max":>26} {"p50 vs rclpy":>13}')
    plain = {row['burst']: row for row in rows if row['config'] == 'rclpy'}
    for row in rows:
        base = plain.get(row['burst'])
        ratio = (f'{row["accept_ms_p50"] / base["accept_ms_p50"]:.2f}x'
                 if base and row['accept_ms_p50'] and base['accept_ms_p50'] else '-')
        latency = ' / '.join('-' if row[key] is None else f'{row[key]:.1f}'
                             for key in ('accept_ms_p50', 'accept_ms_p95', 'accept_ms_max'))
        print(f'{row["config"]:<10} {"burst" if row["burst"] else "one at a time":<14} '
              f'{row["first_arrived"]:>14} {row["complete"]:>9} {row["filter_events"]:>14} '
              f'{latency:>26} {ratio:>13}')
    now = datetime.datetime.now(datetime.timezone.utc)
    out = REPO / 'benchmarks' / 'results' / \
        f'first-feedback-{now:%Y-%m-%d}-{platform.node()}-{args.uuids}.json'
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({'date': now.isoformat(), 'host': platform.node(),
                               'machine': environment_facts(), 'args': vars(args),
                               'load_average': os.getloadavg(), 'rows': rows}, indent=1))
    print(f'\nresults: {out}')


if __name__ == '__main__':
    main()
