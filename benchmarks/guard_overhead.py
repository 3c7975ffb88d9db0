# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""What the server guard costs a publisher: throughput and round-trip latency, guard on and off.

The guard (:mod:`cft_action.guard`) takes one uncontended per-writer mutex around every
``DataWriterImpl::perform_create_new_change``, i.e. once per publish. This script shows whether
that is visible from rclpy:

- **throughput**: a publisher process publishes ``--messages`` std_msgs/String of ``--size`` bytes
  as fast as it can to one matched reader in another process, and times the publish loop;
- **latency**: a ping process publishes a message, a pong process echoes it back, the ping times
  ``--roundtrips`` round trips one after the other (two publishes per round trip);
- **per call** (``micro``): the guard's own cost in nanoseconds, without ROS noise. A stand-in
  ``libfastrtps.so.2.14`` whose ``perform_create_new_change`` does nothing (compiled here with
  the machine's C compiler, as the guard is) is called through the PLT in a C loop, with the
  guard preloaded (it reports itself active on that soname) and without.

Guard ``on`` preloads the guard into the publisher, and into both ping and pong; the sink is never
guarded. The two configurations alternate within each of ``--reps`` repetitions, so that a change
in the machine's load hits both. Every process has a ROS domain that no other process on the host
uses, and localhost-only discovery; every wait is bounded.

    python -m benchmarks.guard_overhead --reps 5
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from typing import Any, Optional

from harness.crash import machine_line, plain_env, server_env
from harness.domain import unused_domain
from harness.proc import Proc, main_or_role, python_module
from harness.report import say


# --- roles ---------------------------------------------------------------------------------------

def _qos() -> Any:
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


def _guard_line() -> str:
    import cft_action.guard as guard
    calls = guard.call_counts()
    return f'{guard.is_active()} {calls.get("perform_create_new_change", 0)}'


def role_sink(topic: str, timeout: float) -> int:
    import rclpy
    from rclpy.node import Node
    from std_msgs.msg import String
    node = Node('overhead_sink')
    got = [0]
    node.create_subscription(String, topic, lambda _m: got.__setitem__(0, got[0] + 1), _qos())
    say('READY')
    deadline = time.monotonic() + timeout
    stop = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    while not stop.is_set() and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    say('RECEIVED', got[0])
    return 0


def role_pub(topic: str, messages: int, size: int) -> int:
    import rclpy
    from rclpy.node import Node
    from std_msgs.msg import String
    node = Node('overhead_pub')
    pub = node.create_publisher(String, topic, _qos())
    deadline = time.monotonic() + 20.0
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    if pub.get_subscription_count() == 0:
        say('NO_READER')
        return 1
    time.sleep(0.5)  # let the reader match this writer too
    msg = String(data='x' * size)
    for _ in range(200):  # warm-up
        pub.publish(msg)
    start = time.perf_counter()
    for _ in range(messages):
        pub.publish(msg)
    elapsed = time.perf_counter() - start
    say('PUB', messages, f'{elapsed:.6f}')
    say('GUARD', _guard_line())
    return 0


def role_pong(topic_in: str, topic_out: str, timeout: float) -> int:
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import String
    node = Node('overhead_pong')
    pub = node.create_publisher(String, topic_out, _qos())
    done = threading.Event()

    def echo(msg: String) -> None:
        if msg.data == 'STOP':
            done.set()
        pub.publish(msg)

    node.create_subscription(String, topic_in, echo, _qos())
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    say('READY')
    deadline = time.monotonic() + timeout
    while not done.is_set() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    say('GUARD', _guard_line())
    return 0


def role_ping(topic_out: str, topic_in: str, roundtrips: int, size: int) -> int:
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import String
    node = Node('overhead_ping')
    pub = node.create_publisher(String, topic_out, _qos())
    replies: list[str] = []
    node.create_subscription(String, topic_in, lambda m: replies.append(m.data), _qos())
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    pad = 'x' * max(0, size - 8)

    def roundtrip(i: int, timeout: float) -> Optional[float]:
        replies.clear()
        data = f'{i:08d}{pad}'
        start = time.perf_counter()
        pub.publish(String(data=data))
        deadline = start + timeout
        while data not in replies:
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                return None
            executor.spin_once(timeout_sec=remaining)
        return time.perf_counter() - start

    # Until the echo works both ways (discovery), then a warm-up.
    deadline = time.monotonic() + 30.0
    while roundtrip(-1, 0.2) is None:
        if time.monotonic() > deadline:
            say('NO_PONG')
            return 1
    for i in range(100):
        roundtrip(i, 1.0)
    rtts = []
    lost = 0
    for i in range(roundtrips):
        rtt = roundtrip(i, 1.0)
        if rtt is None:
            lost += 1
        else:
            rtts.append(rtt)
    pub.publish(String(data='STOP'))
    say('RTT', json.dumps({'rtts_us': [round(r * 1e6, 1) for r in rtts], 'lost': lost}))
    say('GUARD', _guard_line())
    return 0


#: The child processes of this script: ``guard_overhead.py _role NAME ARGS...``.
ROLES = {'sink': role_sink, 'pub': role_pub, 'pong': role_pong, 'ping': role_ping}


# --- per call, in C ------------------------------------------------------------------------------

_STANDIN_C = r"""
#include <stdint.h>
#define PCNC2 "_ZN8eprosima7fastdds3dds14DataWriterImpl25perform_create_new_change" \
  "ENS_8fastrtps4rtps12ChangeKind_tEPvRNS4_11WriteParamsERKNS4_16InstanceHandle_tE"
#define PRFI2 "_ZN8eprosima7fastdds3dds14DataWriterImpl26process_reader_filter_info" \
  "ERKNS_8fastrtps4rtps6GUID_tERKNS4_15ReaderProxyDataE"
#define RRF2 "_ZN8eprosima7fastdds3dds14DataWriterImpl20remove_reader_filter" \
  "ERKNS_8fastrtps4rtps6GUID_tE"
uint32_t pcnc(void *self, int kind, void *data, void *params, const void *handle) __asm__(PCNC2);
uint32_t pcnc(void *self, int kind, void *data, void *params, const void *handle) {
  (void)self; (void)data; (void)params; (void)handle;
  __asm__ volatile("" ::: "memory");
  return (uint32_t)kind;
}
void prfi(void *self, const void *guid, const void *info) __asm__(PRFI2);
void prfi(void *self, const void *guid, const void *info) { (void)self; (void)guid; (void)info; }
void rrf(void *self, const void *guid) __asm__(RRF2);
void rrf(void *self, const void *guid) { (void)self; (void)guid; }
/* Through the PLT, as inside Fast DDS: the preloaded definition wins when there is one. */
long bench_loop(long n, void *writer) {
  long sum = 0;
  for (long i = 0; i < n; i++) sum += pcnc(writer, 0, 0, 0, 0);
  return sum;
}
"""

_MAIN_C = r"""
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
long bench_loop(long n, void *writer);
static double now(void) {
  struct timespec ts; clock_gettime(CLOCK_MONOTONIC, &ts); return ts.tv_sec + ts.tv_nsec * 1e-9;
}
int main(int argc, char **argv) {
  long n = atol(argv[1]);
  int reps = atoi(argv[2]);
  bench_loop(n / 10, (void *)0x1000);  /* warm-up, and the guard resolves Fast DDS */
  int (*state)(void) = (int (*)(void))dlsym(RTLD_DEFAULT, "cft_guard_state");
  printf("STATE %d\n", state ? state() : -1);
  for (int r = 0; r < reps; r++) {
    double t0 = now();
    bench_loop(n, (void *)0x1000);
    printf("NS %.3f\n", (now() - t0) / n * 1e9);
  }
  return 0;
}
"""


def micro(opts: argparse.Namespace) -> Optional[dict[str, Any]]:
    """Nanoseconds per call of a do-nothing perform_create_new_change, guard off and on."""
    from cft_action import guard
    compiler = shutil.which('cc') or shutil.which('gcc')
    if compiler is None:
        print('micro: no C compiler, skipped', flush=True)
        return None
    work = Path(tempfile.mkdtemp(prefix='cft_guard_micro_'))
    try:
        (work / 'standin.c').write_text(_STANDIN_C)
        (work / 'main.c').write_text(_MAIN_C)
        lib = work / 'libfastrtps.so.2.14'
        subprocess.run([compiler, '-O2', '-shared', '-fPIC', '-Wl,-soname,libfastrtps.so.2.14',
                        '-o', str(lib), str(work / 'standin.c')], check=True, timeout=120)
        subprocess.run([compiler, '-O2', '-o', str(work / 'main'), str(work / 'main.c'),
                        str(lib), '-ldl'], check=True, timeout=120)
        results: dict[str, Any] = {'off': [], 'on': [], 'state': {}}
        base = {k: v for k, v in os.environ.items() if k not in ('LD_PRELOAD', 'CFT_GUARD_DEBUG')}
        base['LD_LIBRARY_PATH'] = str(work)  # the stand-in, not the real libfastrtps
        for rep in range(opts.reps):
            for config in (['off', 'on'] if rep % 2 == 0 else ['on', 'off']):
                env = guard.environment(base) if config == 'on' else base
                out = subprocess.run([str(work / 'main'), str(opts.micro_calls), '3'], env=env,
                                     capture_output=True, text=True, timeout=120, check=True)
                lines = out.stdout.split('\n')
                results['state'][config] = next(int(x.split()[1]) for x in lines
                                                if x.startswith('STATE'))
                results[config].append(min(float(x.split()[1]) for x in lines
                                           if x.startswith('NS')))
        return results
    finally:
        shutil.rmtree(work, ignore_errors=True)


# --- harness -------------------------------------------------------------------------------------

def env_for(domain: int, guarded: bool) -> dict[str, str]:
    return server_env(domain, guarded)


def throughput_once(guarded: bool, opts: argparse.Namespace) -> dict[str, Any]:
    domain, topic = unused_domain(), f'ovh_{uuid.uuid4().hex[:8]}'
    role = python_module('benchmarks.guard_overhead', '_role')
    sink = Proc('sink', [*role, 'sink', topic, '120'], plain_env(domain))
    pub = None
    try:
        if not sink.wait_for('READY', 60.0):
            return {'error': 'sink not ready'}
        pub = Proc('pub', [*role, 'pub', topic, str(opts.messages), str(opts.size)],
                   env_for(domain, guarded))
        line = pub.wait_for('PUB', 120.0)
        guard_line = pub.wait_for('GUARD', 10.0)
        if line is None:
            return {'error': 'publisher gave no result: ' + pub.tail(10)}
        _, n, elapsed = line.split()
        sink.close_stdin()
        received = sink.wait_for('RECEIVED', 10.0)
        active, calls = guard_line.split()[1:3] if guard_line else ('?', '?')
        return {'per_s': int(n) / float(elapsed), 'us_per_publish': float(elapsed) / int(n) * 1e6,
                'received': int(received.split()[1]) if received else None,
                'guard_active': active, 'guard_writes': calls}
    finally:
        for proc in (pub, sink):
            if proc is not None:
                proc.stop()


def latency_once(guarded: bool, opts: argparse.Namespace) -> dict[str, Any]:
    domain = unused_domain()
    there, back = f'ovh_ping_{uuid.uuid4().hex[:8]}', f'ovh_pong_{uuid.uuid4().hex[:8]}'
    role = python_module('benchmarks.guard_overhead', '_role')
    pong = Proc('pong', [*role, 'pong', there, back, '120'], env_for(domain, guarded))
    ping = None
    try:
        if not pong.wait_for('READY', 60.0):
            return {'error': 'pong not ready'}
        ping = Proc('ping', [*role, 'ping', there, back, str(opts.roundtrips), str(opts.size)],
                    env_for(domain, guarded))
        line = ping.wait_for('RTT', 120.0)
        guard_line = ping.wait_for('GUARD', 10.0)
        if line is None:
            return {'error': 'ping gave no result: ' + ping.tail(10)}
        data = json.loads(line.split(' ', 1)[1])
        rtts = sorted(data['rtts_us'])
        active, calls = guard_line.split()[1:3] if guard_line else ('?', '?')
        return {'median_us': statistics.median(rtts),
                'p90_us': rtts[int(0.9 * (len(rtts) - 1))],
                'p99_us': rtts[int(0.99 * (len(rtts) - 1))],
                'lost': data['lost'], 'guard_active': active, 'guard_writes': calls}
    finally:
        for proc in (ping, pong):
            if proc is not None:
                proc.stop()


def spread(values: list[float], fmt: str) -> str:
    if not values:
        return 'n/a'
    return (f'{format(statistics.median(values), fmt)} '
            f'({format(min(values), fmt)}–{format(max(values), fmt)})')


def main(argv: list[str]) -> int:
    """Run the benchmark with the command line ``argv``."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--messages', type=int, default=20000, help='publishes per throughput run')
    parser.add_argument('--roundtrips', type=int, default=2000, help='round trips per latency run')
    parser.add_argument('--size', type=int, default=16, help='bytes of string payload')
    parser.add_argument('--reps', type=int, default=5, help='repetitions of each configuration')
    parser.add_argument('--only', choices=['throughput', 'latency', 'micro'],
                        help='run one of the three')
    parser.add_argument('--micro-calls', type=int, default=20_000_000,
                        help='calls per timing of the per-call measurement')
    parser.add_argument('--json', metavar='PATH', help='also write the results as JSON')
    opts = parser.parse_args(argv)
    header = {'date_utc': datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M'),
              'machine': machine_line(),
              'command': 'python -m benchmarks.guard_overhead ' + ' '.join(argv)}
    print(json.dumps(header), flush=True)
    results: dict[str, dict[str, list[dict[str, Any]]]] = {
        'throughput': {'off': [], 'on': []}, 'latency': {'off': [], 'on': []}}
    kinds = [opts.only] if opts.only else ['throughput', 'latency', 'micro']
    micro_results = micro(opts) if 'micro' in kinds else None
    if micro_results:
        print(f'micro: {json.dumps(micro_results)}', flush=True)
    kinds = [k for k in kinds if k != 'micro']
    for rep in range(opts.reps):
        order = ['off', 'on'] if rep % 2 == 0 else ['on', 'off']
        for kind in kinds:
            for config in order:
                once = throughput_once if kind == 'throughput' else latency_once
                r = once(config == 'on', opts)
                results[kind][config].append(r)
                print(f'rep {rep + 1} {kind} guard={config}: {json.dumps(r)}', flush=True)

    print()
    print('| measure | guard off: median (min–max) | guard on: median (min–max) '
          '| on vs off (medians) |')
    print('|---|---|---|---|')
    rows = []
    if 'throughput' in kinds:
        rows += [('throughput', 'per_s', 'publishes/s', '.0f'),
                 ('throughput', 'us_per_publish', 'µs per publish', '.2f')]
    if 'latency' in kinds:
        rows += [('latency', 'median_us', 'round trip, median of run (µs)', '.0f'),
                 ('latency', 'p90_us', 'round trip, p90 of run (µs)', '.0f'),
                 ('latency', 'p99_us', 'round trip, p99 of run (µs)', '.0f')]
    if micro_results:
        off, on = micro_results['off'], micro_results['on']
        print(f'| per call, C loop over a do-nothing perform_create_new_change (ns) | '
              f'{spread(off, ".1f")} | {spread(on, ".1f")} | '
              f'{statistics.median(on) - statistics.median(off):+.1f} ns |')
    for kind, key, label, fmt in rows:
        off = [r[key] for r in results[kind]['off'] if key in r]
        on = [r[key] for r in results[kind]['on'] if key in r]
        delta = (f'{(statistics.median(on) / statistics.median(off) - 1) * 100:+.1f} %'
                 if off and on else 'n/a')
        print(f'| {label} | {spread(off, fmt)} | {spread(on, fmt)} | {delta} |')
    checks = {kind: {config: [(r.get('guard_active'), r.get('guard_writes')) for r in runs]
                     for config, runs in by.items()}
              for kind, by in results.items() if kind in kinds}
    print(f'\nguard active / writes through the guard per run: {json.dumps(checks)}')
    if opts.json:
        Path(opts.json).write_text(json.dumps({'header': header, 'results': results,
                                               'micro': micro_results}, indent=1))
        print(f'results written to {opts.json}')
    return 0


if __name__ == '__main__':
    sys.exit(main_or_role(main, ROLES))
