#!/usr/bin/env python3
# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Demo: a node-filtered ParameterEventHandler against rclpy's, in a busy parameter system.

Twenty nodes (in one helper process) each change a parameter at 10 Hz, so ``/parameter_events``
carries 200 events per second. Two handler processes watch the same 2 of those nodes:

- ``filtered``: :class:`cft_action.ParameterEventHandler`, whose subscription is content-filtered
  on the ``node`` field, so the publishers' writers send it only the 2 nodes' events;
- ``rclpy``: :class:`rclpy.parameter_event_handler.ParameterEventHandler`, which receives all 200
  per second and drops 90 % of them in Python.

Each prints the events its subscription received, the parameter callbacks that fired, and the CPU
time its whole process used (all threads, DDS included) over the same measurement window.

    .venv/bin/python -m demos.parameter_events            # about 35 s
    .venv/bin/python -m demos.parameter_events --seconds 5 --soak 250 --soak-period 0.05 --no-guard

Every filter change (and every filtered reader that comes or goes) is an event at every
``/parameter_events`` writer, that is, at every node; with Fast DDS 2.14 such an event can crash a
process that is publishing at that moment (eProsima/Fast-DDS#4878, docs/INTERNALS.md section 10).
So the nodes' process runs under :mod:`cft_action.guard` unless ``--no-guard`` is given.
``--soak N`` then changes the filtered handler's node set 2*N times while the nodes keep
publishing, and reports whether the nodes' process survived: run it with ``--no-guard`` to see
the hazard.

The demo uses its own ``ROS_DOMAIN_ID`` (random, unless set) and localhost-only discovery.
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import subprocess
import sys
import threading
import time
from typing import Any, Optional, Union

from harness.domain import unused_domain

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # the repository
NODES = 20
RATE_HZ = 10.0
NAMESPACE = '/demo_farm'
WATCHED = (3, 11)


def node_name(i: int) -> str:
    return f'{NAMESPACE}/node_{i:02d}'


# --- child: the nodes that change parameters ----------------------------------------------------

def run_farm(count: int, rate: float) -> None:
    import rclpy
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    rclpy.init()
    nodes = [Node(node_name(i).rsplit('/', 1)[1], namespace=NAMESPACE) for i in range(count)]
    for node in nodes:
        node.declare_parameter('value', 0)
    stop = threading.Event()
    published = [0]

    def publish() -> None:
        # One loop at a fixed period for all nodes: each node changes its parameter at `rate`.
        period, tick, value = 1.0 / rate, time.monotonic(), 0
        while not stop.is_set():
            value += 1
            for node in nodes:
                node.set_parameters([Parameter('value', value=value)])
                published[0] += 1
            tick += period
            stop.wait(max(0.0, tick - time.monotonic()))

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    print('READY', flush=True)
    for line in sys.stdin:
        if line.strip() == 'stats':
            print(f'STATS {json.dumps({"published": published[0], "cpu": time.process_time()})}',
                  flush=True)
    stop.set()
    thread.join(timeout=5)
    for node in nodes:
        node.destroy_node()
    rclpy.shutdown()


# --- child: one handler -------------------------------------------------------------------------

def run_handler(kind: str, watched: list[str], extra: str) -> None:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    rclpy.init()
    node = Node(f'demo_handler_{kind}')
    from cft_action.parameters.parameter_events import ParameterEventHandler as Filtered
    from harness.ros import leave_spinning_process
    from rclpy.parameter_event_handler import ParameterEventHandler as Plain
    handler = (Filtered if kind == 'filtered' else Plain)(node)
    counts = {'received': 0, 'callbacks': 0}
    seen: set[str] = set()

    # The same thin wrapper on both subscriptions counts what the middleware delivered.
    subscription = handler.parameter_event_subscription
    deliver = subscription.callback

    def counted(event) -> None:
        counts['received'] += 1
        deliver(event)
    subscription.callback = counted

    for name in watched:
        def on_change(parameter, name=name) -> None:
            counts['callbacks'] += 1
            seen.add(name)
        handler.add_parameter_callback('value', name, on_change)

    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    print('READY', flush=True)
    deadline = time.monotonic() + 30
    while seen != set(watched) and time.monotonic() < deadline:
        time.sleep(0.05)
    print('WARM' if seen == set(watched) else 'COLD', flush=True)

    base = {'received': 0, 'callbacks': 0, 'cpu': 0.0, 'wall': time.monotonic()}

    def report() -> dict[str, Any]:
        result: dict[str, Any] = {k: counts[k] - base[k] for k in ('received', 'callbacks')}
        result['cpu'] = time.process_time() - base['cpu']
        result['wall'] = time.monotonic() - base['wall']
        if isinstance(handler, Filtered):
            state = handler.parameter_event_filter_state
            result.update(mode=state.mode, active=state.active, updates=state.updates,
                          expression=state.expression, parameters=list(state.expression_parameters))
        return result

    for line in sys.stdin:
        command = line.split()
        if not command:
            continue
        if command[0] == 'start':
            base.update(received=counts['received'], callbacks=counts['callbacks'],
                        cpu=time.process_time(), wall=time.monotonic())
        elif command[0] == 'report':
            print(f'REPORT {json.dumps(report())}', flush=True)
        elif command[0] == 'soak' and isinstance(handler, Filtered):
            # Grow and shrink the node set: each add or remove of the extra node is one update.
            cycles, period = int(command[1]), float(command[2])
            before = handler.parameter_event_filter_state.updates
            for _ in range(cycles):
                handle = handler.add_parameter_callback('value', extra, lambda p: None)
                time.sleep(period)
                handler.remove_parameter_callback(handle)
                time.sleep(period)
                print(f'STEP {handler.parameter_event_filter_state.updates - before}', flush=True)
            print(f'SOAKED {handler.parameter_event_filter_state.updates - before}', flush=True)
    def destroy() -> None:
        handler.destroy()
        node.destroy_node()
    leave_spinning_process(executor, [spinner], destroy)  # else it aborts at exit


# --- the demo -----------------------------------------------------------------------------------

class Child:
    """This script in another process, in one of its child roles, driven by stdin lines."""

    def __init__(self, args: list[str], env: Optional[dict] = None) -> None:
        self.args = args
        self.lines: queue.Queue[str] = queue.Queue()
        self.proc = subprocess.Popen(
            # A module of the repository, as the demo itself: harness/ is imported from there.
            [sys.executable, '-u', '-m', 'demos.parameter_events', *args], cwd=ROOT,
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env=env, start_new_session=True)
        self.stderr: list[str] = []
        threading.Thread(target=self._pump, args=(self.proc.stdout, self.lines.put),
                         daemon=True).start()
        threading.Thread(target=self._pump, args=(self.proc.stderr, self.stderr.append),
                         daemon=True).start()

    @staticmethod
    def _pump(stream, sink) -> None:
        for line in stream:
            sink(line.rstrip('\n'))

    def expect(self, prefix: Union[str, tuple[str, ...]], timeout: float) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=0.2)
            except queue.Empty:
                if self.proc.poll() is not None:
                    break
                continue
            if line.startswith(prefix):
                return line
        raise RuntimeError(f'no {prefix!r} from {self.args} (exit {self.proc.poll()}): '
                           f'{self.stderr[-5:]}')

    def send(self, line: str) -> None:
        assert self.proc.stdin is not None  # a pipe: Popen(stdin=PIPE)
        self.proc.stdin.write(line + '\n')
        self.proc.stdin.flush()

    def request(self, line: str, reply: str, timeout: float = 10.0) -> dict:
        self.send(line)
        return json.loads(self.expect(reply, timeout).split(' ', 1)[1])

    def stop(self) -> Optional[int]:
        if self.proc.poll() is None:
            try:
                if self.proc.stdin is not None:
                    self.proc.stdin.close()
            except OSError:
                pass
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.terminate()
                try:
                    self.proc.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait(timeout=5)
        return self.proc.returncode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seconds', type=float, default=20.0, help='measurement window')
    parser.add_argument('--soak', type=int, default=0, metavar='N',
                        help='then change the filtered handler node set 2*N times')
    parser.add_argument('--soak-period', type=float, default=0.1,
                        help='seconds between soak updates')
    parser.add_argument('--no-guard', dest='guard', action='store_false',
                        help="run the nodes' process without the cft_action guard")
    parser.add_argument('--farm', nargs=2, metavar=('COUNT', 'RATE'), help=argparse.SUPPRESS)
    parser.add_argument('--handler', nargs='+', metavar='KIND', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.farm:
        return run_farm(int(args.farm[0]), float(args.farm[1]))
    if args.handler:
        return run_handler(args.handler[0], args.handler[1:-1], args.handler[-1])

    os.environ.setdefault('ROS_DOMAIN_ID', str(unused_domain()))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    watched = [node_name(i) for i in WATCHED]
    extra = node_name(0)
    print(f'ROS_DOMAIN_ID={os.environ["ROS_DOMAIN_ID"]}: {NODES} nodes changing a parameter at '
          f'{RATE_HZ:g} Hz (guard {"on" if args.guard else "off"}); both handlers watch '
          f'{", ".join(watched)}', flush=True)
    farm_env = None
    if args.guard:
        from cft_action import guard
        farm_env = guard.environment()
    children: list[Child] = []
    try:
        farm = Child(['--farm', str(NODES), str(RATE_HZ)], env=farm_env)
        children.append(farm)
        farm.expect('READY', 30)
        handlers = {kind: Child(['--handler', kind, *watched, extra])
                    for kind in ('filtered', 'rclpy')}
        children.extend(handlers.values())
        for child in handlers.values():
            child.expect('READY', 30)
        for kind, child in handlers.items():
            if child.expect(('WARM', 'COLD'), 35) != 'WARM':
                raise RuntimeError(f'the {kind} handler saw no events of {watched}')
        print('both handlers receive their nodes; measuring', flush=True)
        farm_start = farm.request('stats', 'STATS')
        for child in handlers.values():
            child.send('start')
        end = time.monotonic() + args.seconds
        while (left := end - time.monotonic()) > 0:
            time.sleep(min(5.0, left))
            now = {k: c.request('report', 'REPORT') for k, c in handlers.items()}
            print(f'  t={now["filtered"]["wall"]:5.1f} s  received: filtered '
                  f'{now["filtered"]["received"]:5d}, rclpy {now["rclpy"]["received"]:5d}',
                  flush=True)
        final = {k: c.request('report', 'REPORT') for k, c in handlers.items()}
        farm_end = farm.request('stats', 'STATS')
        published = farm_end['published'] - farm_start['published']
        print(f'\nevents published by the {NODES} nodes: {published} in {args.seconds:g} s; '
              f'of them, by the 2 watched nodes: about {published * 2 // NODES}')
        print(f'{"handler":<10}{"received":>10}{"callbacks":>11}{"CPU s":>8}{"CPU %":>7}')
        for kind, r in final.items():
            print(f'{kind:<10}{r["received"]:>10}{r["callbacks"]:>11}{r["cpu"]:>8.2f}'
                  f'{100 * r["cpu"] / r["wall"]:>7.1f}')
        f, u = final['filtered'], final['rclpy']
        print(f'filtered/rclpy: messages {f["received"] / max(1, u["received"]):.3f}, '
              f'CPU {f["cpu"] / max(1e-9, u["cpu"]):.2f}')
        print(f'filter: mode={f["mode"]} active={f["active"]} updates={f["updates"]} '
              f'expression={f["expression"]!r} parameters={f["parameters"]}')
        print(f'nodes process CPU over the window: {farm_end["cpu"] - farm_start["cpu"]:.2f} s')
        if args.soak:
            print(f'\nsoak: {2 * args.soak} filter updates, one every {args.soak_period:g} s, '
                  f'while the nodes publish (guard {"on" if args.guard else "off"})', flush=True)
            child = handlers['filtered']
            child.send(f'soak {args.soak} {args.soak_period}')
            steps, died_after = 0, None
            deadline = time.monotonic() + 2 * args.soak * args.soak_period + 60
            while True:
                line = child.expect('S', max(0.1, deadline - time.monotonic()))
                if line.startswith('STEP'):
                    steps = int(line.split()[1])
                    if died_after is None and farm.proc.poll() is not None:
                        died_after = steps
                        break
                    elif steps % 100 == 0:
                        print(f'  {steps} updates, nodes process alive', flush=True)
                elif line.startswith('SOAKED'):
                    break
            time.sleep(1.0)
            if farm.proc.poll() is None:
                print(f'soak: {steps} updates sent; the nodes process is alive')
            else:
                print(f'soak: the nodes process DIED (exit {farm.proc.returncode}) within '
                      f'{died_after or steps} updates')
    except BaseException:
        if children and children[0].proc.poll() is not None:
            print(f'the nodes process died (exit {children[0].proc.returncode})', flush=True)
        raise
    finally:
        for child in reversed(children):
            child.stop()


if __name__ == '__main__':
    main()
