"""Rate-limited and polled subscriptions (issue 35): bytes on the wire, the publisher's CPU, polls.

Three parts in one run, every process in its own network namespace (:mod:`harness.netns`: UDP
only, each client's ``rx_bytes`` on its own veth), the publishers run under ``cft-action guard``:

1. **Bytes.** One publisher of ``--size`` B messages (``std_msgs/String``, serialized size with its
   encapsulation) at ``--hz``, and side by side a subscriber with ``max_rate=--max-rate``, a plain
   subscriber, and a throttle relay (:class:`harness.throttle.ThrottleRelay`, as topic_tools'
   throttle: a plain subscriber that republishes at ``--max-rate``), and a plain subscriber of the
   output of a second relay, which runs beside the publisher (as a throttle on the robot serves a
   GUI on a thin link; the clients' namespaces cannot reach each other): it receives
   ``--max-rate`` messages a second as a relay delivers them. Each
   one's bytes received per second over ``--window`` s. The ideal is ``--max-rate`` messages a
   second at what one message costs the plain subscriber on the wire (its bytes divided by its
   messages: Ethernet, IP, UDP, RTPS headers, and its share of heartbeats and discovery); the
   relay's subscriber pays the same discovery as the rate-limited one, spread over few messages.
2. **CPU.** The publisher's user + system seconds (``/proc/PID/stat``) per second over
   ``--cpu-window`` s, with 1, 8 and 32 (``--counts``) rate-limited subscribers and with as many
   plain ones, alternating; ``--per-process`` subscribers (each its own participant, rclpy context)
   share a process and a namespace.
3. **Polls.** Two publishers at ``--hz``, one subscriber with ``poll=0``, ``--rounds`` polls of
   ``--poll-n`` in a row: after each, the messages of each publisher that arrive until the next
   (``--poll-settle`` s after the last expected one); the time from ``poll()`` to the first.

Needs root. The results (machine, date, command, every raw figure) go to
``benchmarks/results/rate-<date>-<host>.json``; the tables are printed in Markdown::

    nice -n 10 python -m benchmarks.rate

``--markdown FILE`` prints the tables of a results file.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import resource
import statistics
import sys
import threading
import time
from functools import partial
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

from harness import netns
from harness.cli import int_list
from harness.domain import unused_domain
from harness.machine import environment_facts
from harness.polling import wait_until
from harness.proc import main_or_role, Proc, python_module
from harness.procstat import cpu_s
from harness.report import fmt, markdown_table

REPO = Path(__file__).resolve().parent.parent
#: Reliable with a short history, as tests/test_rate_limit.py: filtered readers must not stall.
DEPTH = 10
#: The subscriber kinds of part 1, in the order they are started (``relayed``: of the output of a
#: relay in the publisher's namespace, not of the publisher's topic).
KINDS = ('rate', 'plain', 'relay', 'relayed')


# --- the roles (each runs in a process of its own) ------------------------------------------------

def _qos() -> Any:
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=DEPTH, reliability=ReliabilityPolicy.RELIABLE)


def _own_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _commands(handlers: dict[str, Callable[[str], Any]]) -> None:
    """Answer ``stats`` and the handlers' commands on stdin until it closes."""
    for line in sys.stdin:
        command, _, argument = line.strip().partition(' ')
        if command in handlers:
            print(f'{command.upper()} ' + json.dumps(handlers[command](argument)), flush=True)


def publisher(topic: str, hz: float, size: int, tag: int) -> int:
    """Publish ``tag:...`` strings of ``size`` serialized bytes at ``hz`` (absolute schedule) until
    stdin closes. ``stats``: messages sent, matched subscriptions, CPU seconds;
    ``wait N``: whether exactly N subscriptions are matched within 60 s."""
    from rclpy.node import Node
    from std_msgs.msg import String
    node = Node(f'cft_rate_publisher_{tag}')
    pub = node.create_publisher(String, topic, _qos())
    # CDR: 4 bytes encapsulation, 4 of length, the characters and their terminating NUL.
    head = f'{tag}:'
    message = String(data=head + 'x' * max(0, size - 9 - len(head)))
    sent = [0]
    stop = threading.Event()

    def run() -> None:
        start = time.monotonic()
        while not stop.is_set():
            stop.wait(max(0.0, start + sent[0] / hz - time.monotonic()))
            pub.publish(message)
            sent[0] += 1

    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    print('READY', flush=True)
    writer = next(bytes(info.endpoint_gid[:16]).hex()
                  for info in node.get_publishers_info_by_topic(topic)
                  if info.node_name == node.get_name())
    _commands({
        'stats': lambda _: {'sent': sent[0], 'matched': pub.get_subscription_count(),
                            'cpu_s': _own_cpu_s(), 'writer': writer},
        'wait': lambda n: {'matched': wait_until(lambda: pub.get_subscription_count() == int(n),
                                                 60.0)},
    })
    stop.set()
    worker.join(5.0)
    node.destroy_node()
    return 0


def subscriber(topic: str, kind: str, participants: int, max_rate: float) -> int:
    """``participants`` subscriptions to ``topic`` (each its own rclpy context, hence participant),
    of ``kind``: ``rate`` (``max_rate``), ``plain``, ``relay`` (a throttle relay at ``max_rate``),
    or ``relayed`` (plain, of the relay's output). ``stats``: messages each received, CPU
    seconds, where the filter runs."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import String

    from cft_action import create_filtered_subscription, rate_filter_state
    from harness.throttle import ThrottleRelay
    received: list[int] = [0] * participants
    states: list[Callable[[], str]] = []
    relays: dict[int, ThrottleRelay] = {}  # their own counts
    executors = []
    for index in range(participants):
        context = rclpy.Context()
        rclpy.init(context=context)
        node = Node(f'cft_rate_{kind}_{index}', context=context)

        def count(_message: Any, index: int = index) -> None:
            received[index] += 1

        if kind == 'rate':
            sub = create_filtered_subscription(node, String, topic, count, _qos(),
                                               max_rate=max_rate)
            states.append(partial(lambda s, n: str(rate_filter_state(s, n).filtered_in), sub, node))
        elif kind == 'relay':
            relay = ThrottleRelay(node, String, topic, topic + '_throttled', max_rate, _qos())
            relays[index] = relay
            states.append(partial(lambda r: f'relay, republished {r.republished}', relay))
        else:
            node.create_subscription(String, topic + ('_throttled' if kind == 'relayed' else ''),
                                     count, _qos())
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        threading.Thread(target=executor.spin, daemon=True).start()
        executors.append((executor, context))
    print('READY', flush=True)
    _commands({'stats': lambda _: {'received': [relays[i].received if i in relays else count
                                                for i, count in enumerate(received)],
                                   'cpu_s': _own_cpu_s(),
                                   'filtered_in': [state() for state in states]}})
    for executor, context in executors:
        for node in executor.get_nodes():
            node.destroy_node()  # the publisher sees it go at once, not at the lease's end
        executor.shutdown(1.0)
        rclpy.try_shutdown(context=context)
    return 0


def poller(topic: str, rounds: int, n: int, settle: float) -> int:
    """On ``go``: ``rounds`` polls of ``n`` on a ``poll=0`` subscription to ``topic``; prints
    ``RESULT`` with each round's messages per publisher and its latencies."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import String

    from cft_action import create_filtered_subscription, poll, rate_filter_state
    node = Node('cft_rate_poller')
    arrivals: list[tuple[float, str]] = []
    sub = create_filtered_subscription(
        node, String, topic, lambda m: arrivals.append((time.monotonic(), m.data.split(':')[0])),
        _qos(), poll=0)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    print('READY', flush=True)
    while sys.stdin.readline().strip() != 'go':
        pass
    end = time.monotonic() + 1.0
    while time.monotonic() < end:  # nothing may come before the first poll
        executor.spin_once(timeout_sec=0.05)
    result: dict[str, Any] = {'before_first_poll': len(arrivals), 'rounds': []}
    arrivals.clear()
    for _ in range(rounds):
        mark = len(arrivals)
        started = time.monotonic()
        poll(sub, n)
        deadline = started + 5.0
        while len(arrivals) - mark < 2 * n and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.005)
        quiet = time.monotonic() + settle
        while time.monotonic() < quiet:
            executor.spin_once(timeout_sec=0.02)
        mine = arrivals[mark:]
        result['rounds'].append({
            'per_publisher': {tag: sum(1 for _, t in mine if t == tag) for tag in ('0', '1')},
            'first_ms': 1000 * (mine[0][0] - started) if mine else None,
            'last_ms': 1000 * (mine[-1][0] - started) if mine else None})
    result['filtered_in'] = rate_filter_state(sub, node).filtered_in
    print('RESULT ' + json.dumps(result), flush=True)
    node.destroy_node()
    return 0


ROLES: dict[str, Callable[..., int]] = {'publisher': publisher, 'subscriber': subscriber,
                                        'poller': poller}


# --- the run --------------------------------------------------------------------------------------

class Run:
    """The namespaces, the guarded publishers in the server's, and the clients of one part."""

    def __init__(self, args: argparse.Namespace, progress: Callable[[str], None]) -> None:
        """Create the topology."""
        reason = netns.unavailable_reason()
        if reason is not None:
            raise RuntimeError(f'network namespaces are not available: {reason}')
        netns.remove_stale()
        self.args = args
        self.progress = progress
        self.topology = netns.Topology()
        self.env = {**os.environ, **netns.ENVIRONMENT, 'ROS_DOMAIN_ID': str(unused_domain())}
        self.procs: list[Proc] = []
        self.namespaces: dict[str, str] = {}  # a process's name: its namespace

    def start(self, name: str, role: str, *role_args: object, server: bool = False) -> Proc:
        """Start a role in the server's namespace (guarded) or in a new client namespace."""
        from cft_action import guard
        argv = python_module('benchmarks.rate', '_role', role, *role_args)
        namespace = self.topology.server if server else self.topology.add_client()
        proc = Proc(name, self.topology.command(namespace, argv),
                    guard.environment(self.env) if server else self.env)
        self.procs.append(proc)
        self.namespaces[name] = namespace
        proc.expect('READY', 90)
        return proc

    def capture(self, name: str, writer: str) -> Proc:
        """A packet capture (harness/capture.py) in the namespace of the process ``name``, with
        ``writer`` (a GUID in hex) as the one whose traffic it counts apart; stopped with the
        clients."""
        argv = python_module('harness.capture', netns.INTERFACE, writer, '')
        proc = Proc(f'capture of {name}', self.topology.command(self.namespaces[name], argv),
                    self.env)
        self.procs.append(proc)
        proc.expect('SNIFFING', 30)
        return proc

    def stop_clients(self) -> None:
        """Stop every process outside the server's namespace and delete their namespaces."""
        for proc in [p for p in self.procs if not p.name.startswith('publisher')]:
            proc.stop()
            self.procs.remove(proc)
        self.topology.close_clients()

    def close(self) -> None:
        """Stop every process and delete the namespaces."""
        for proc in self.procs:
            proc.stop()
        self.procs.clear()
        self.topology.close()


def _matched(pub: Proc, count: int) -> None:
    if not pub.request_json(f'wait {count}', 'WAIT', 90)['matched']:
        raise RuntimeError(f'{count} subscriptions not matched: '
                           f"{pub.request_json('stats', 'STATS')['matched']}")


def part_bytes(run: Run, pub: Proc, topic: str) -> dict[str, Any]:
    """Part 1: the bytes per second each kind of subscriber receives, side by side."""
    out = bytes_received(run, pub, topic, KINDS)
    plain = out['kinds']['plain']
    out['bytes_per_message_plain'] = plain['rx_bytes_per_s'] / plain['messages_per_s']
    out['ideal_bytes_per_s'] = run.args.max_rate * out['bytes_per_message_plain']
    rate = out['kinds']['rate']['rx_bytes_per_s']
    out['rate_to_ideal'] = rate / out['ideal_bytes_per_s']
    out['rate_topic_to_ideal'] = (out['kinds']['rate']['topic_bytes_per_s']
                                  / out['ideal_bytes_per_s'])
    out['rate_to_plain'] = rate / plain['rx_bytes_per_s']
    out['rate_to_relay'] = rate / out['kinds']['relay']['rx_bytes_per_s']
    out['rate_to_relayed'] = rate / out['kinds']['relayed']['rx_bytes_per_s']
    return out


def bytes_received(run: Run, pub: Proc, topic: str, kinds: Sequence[str]) -> dict[str, Any]:
    """The bytes and messages per second that subscribers of ``kinds`` receive, side by side."""
    args = run.args
    relayed = 'relayed' in kinds
    if relayed:  # the relay it subscribes to, beside the publisher
        run.start('relay beside the publisher', 'subscriber', topic, 'relay', 1, args.max_rate,
                  server=True)
    subs = {kind: run.start(kind, 'subscriber', topic, kind, 1, args.max_rate) for kind in kinds}
    _matched(pub, len(kinds))  # the relayed subscriber's relay in its place
    # The rate-limited subscriber's frames by writer: the topic's, and discovery's, which every
    # participant receives whatever it subscribes to.
    capture = run.capture('rate', pub.request_json('stats', 'STATS')['writer'])
    captured_from = time.monotonic()
    time.sleep(args.warmup)
    before = {k: (netns.interface_counters(p.pid), p.request_json('stats', 'STATS'))
              for k, p in subs.items()}
    started = time.monotonic()
    time.sleep(args.window)
    after = {k: (netns.interface_counters(p.pid), p.request_json('stats', 'STATS'))
             for k, p in subs.items()}
    seconds = time.monotonic() - started
    anatomy = capture.request_json('stop', 'RESULT', timeout=30)
    captured_s = time.monotonic() - captured_from
    out: dict[str, Any] = {'window_s': seconds, 'kinds': {}, 'rate_anatomy': anatomy}
    for kind in kinds:
        (net0, st0), (net1, st1) = before[kind], after[kind]
        assert net0 is not None and net1 is not None
        out['kinds'][kind] = {
            'rx_bytes_per_s': (net1['rx_bytes'] - net0['rx_bytes']) / seconds,
            'rx_packets_per_s': (net1['rx_packets'] - net0['rx_packets']) / seconds,
            'messages_per_s': (st1['received'][0] - st0['received'][0]) / seconds,
            'cpu_s_per_s': (st1['cpu_s'] - st0['cpu_s']) / seconds,
            'filtered_in': st1['filtered_in'][0] if st1['filtered_in'] else 'plain'}
    # The capture spans the warm-up too: the topic's traffic is steady, discovery's is not.
    topic_bytes = anatomy['feedback data']['bytes'] + anatomy['feedback gap/heartbeat']['bytes']
    out['kinds']['rate']['topic_bytes_per_s'] = topic_bytes / captured_s
    run.stop_clients()
    return out


def part_cpu(run: Run, pub: Proc, topic: str) -> list[dict[str, Any]]:
    """Part 2: the publisher's CPU per second with N rate-limited and N plain subscribers."""
    args = run.args
    rows = []
    plan = [(0, 'none')] + [(n, kind) for n in args.counts for kind in ('rate', 'plain')]
    for n, kind in plan:
        run.progress(f'cpu: {n} {kind} subscriber(s)')
        left = n
        while left > 0:
            share = min(left, args.per_process)
            run.start(f'{kind} x{share}', 'subscriber', topic, kind, share, args.max_rate)
            left -= share
        _matched(pub, n)
        time.sleep(args.warmup)
        cpu0, clock0 = cpu_s(pub.pid), time.monotonic()
        time.sleep(args.cpu_window)
        cpu1, seconds = cpu_s(pub.pid), time.monotonic() - clock0
        assert cpu0 is not None and cpu1 is not None
        stats = [p.request_json('stats', 'STATS') for p in run.procs
                 if not p.name.startswith('publisher')]
        rows.append({'subscribers': n, 'kind': kind, 'window_s': seconds,
                     'publisher_cpu_s_per_s': (cpu1 - cpu0) / seconds,
                     'filtered_in': sorted({f for s in stats for f in s['filtered_in']}),
                     'load_average_at_end': os.getloadavg()})
        run.progress(f'    publisher CPU {rows[-1]["publisher_cpu_s_per_s"]:.3f} s/s')
        run.stop_clients()
    for row in rows:
        twin = next((r for r in rows if r['subscribers'] == row['subscribers']
                     and r['kind'] == 'plain'), None)
        row['to_plain'] = (row['publisher_cpu_s_per_s'] / twin['publisher_cpu_s_per_s']
                           if twin and row['kind'] == 'rate' else None)
    return rows


def part_polls(run: Run, topic: str) -> dict[str, Any]:
    """Part 3: polls of n with two publishers."""
    args = run.args
    pubs = [run.start(f'publisher {tag}', 'publisher', topic, args.hz, args.size, tag,
                      server=True) for tag in (0, 1)]
    sub = run.start('poller', 'poller', topic, args.rounds, args.poll_n, args.poll_settle)
    for pub in pubs:
        _matched(pub, 1)
    time.sleep(args.warmup)
    sub.send('go')
    result = json.loads(sub.expect('RESULT', 60 + args.rounds * (5 + args.poll_settle))
                        .split(' ', 1)[1])
    rounds = result['rounds']
    wanted = {'0': args.poll_n, '1': args.poll_n}
    result['mismatches'] = sum(r['per_publisher'] != wanted for r in rounds)
    firsts = sorted(r['first_ms'] for r in rounds if r['first_ms'] is not None)
    lasts = sorted(r['last_ms'] for r in rounds if r['last_ms'] is not None)
    result['first_ms_median'] = statistics.median(firsts) if firsts else None
    result['first_ms_max'] = firsts[-1] if firsts else None
    result['last_ms_median'] = statistics.median(lasts) if lasts else None
    run.stop_clients()
    for pub in pubs:
        pub.stop()
        run.procs.remove(pub)
    return result


# --- presentation ---------------------------------------------------------------------------------

def markdown(results: dict[str, Any]) -> str:
    """The three parts' tables."""
    args, out = results['args'], []
    part = results.get('bytes')
    if part:
        kinds = part['kinds']
        out += markdown_table(
            ['subscriber', 'B/s received', 'messages/s', 'filtered in'],
            [[f"`max_rate={args['max_rate']:g}`" if k == 'rate' else
              {'relay': 'throttle relay', 'relayed': "the relay's subscriber"}.get(k, 'plain'),
              f"{kinds[k]['rx_bytes_per_s']:,.0f}", f"{kinds[k]['messages_per_s']:.1f}",
              kinds[k]['filtered_in']] for k in KINDS], ['---', '---:', '---:', '---'])
        out.append(f"\nideal {args['max_rate']:g} x {part['bytes_per_message_plain']:.0f} B = "
                   f"{part['ideal_bytes_per_s']:,.0f} B/s; rate-limited / ideal "
                   f"{part['rate_to_ideal']:.2f}, / plain {part['rate_to_plain']:.4f}, / relay "
                   f"{part['rate_to_relay']:.4f}, / the relay's subscriber "
                   f"{fmt(part.get('rate_to_relayed'), '.2f')}; the topic writer's frames "
                   f"alone (a capture from the warm-up on; the rest is discovery) / ideal "
                   f"{fmt(part.get('rate_topic_to_ideal'), '.2f')}\n")
    alone = results.get('bytes_alone')
    if alone:
        mine = alone['kinds']['rate']
        out.append(f"`max_rate` alone on the writer: {mine['rx_bytes_per_s']:,.0f} B/s, "
                   f"{mine['messages_per_s']:.2f} messages/s, / ideal {alone['rate_to_ideal']:.2f}"
                   f", the topic writer's frames alone "
                   f"{fmt(alone.get('rate_topic_to_ideal'), '.2f')}\n")
    rows = results.get('cpu')
    if rows:
        counts = sorted({r['subscribers'] for r in rows if r['subscribers']})

        def cpu(n: int, kind: str) -> Optional[float]:
            row = next((r for r in rows if r['subscribers'] == n and r['kind'] == kind), None)
            return None if row is None else 1000 * row['publisher_cpu_s_per_s']

        idle = cpu(0, 'none')
        out.append(f"publisher CPU, ms/s (no subscriber: {fmt(idle, '.1f')})\n")
        table = []
        for n in counts:
            rate, plain = cpu(n, 'rate'), cpu(n, 'plain')
            table.append([str(n), fmt(rate, '.1f'), fmt(plain, '.1f'),
                          fmt(rate / plain if rate is not None and plain else None, '.2f')])
        out += markdown_table(['subscribers', 'rate-limited', 'plain', 'ratio'], table,
                              ['---:', '---:', '---:', '---:'])
        out.append('')
    polls = results.get('polls')
    if polls:
        out.append(f"polls: {len(polls['rounds'])} x {args['poll_n']} per publisher, "
                   f"2 publishers: {polls['mismatches']} mismatched rounds, "
                   f"{polls['before_first_poll']} before the first poll; poll() to first "
                   f"message median {fmt(polls['first_ms_median'], '.1f')} ms, max "
                   f"{fmt(polls['first_ms_max'], '.1f')} ms; to the last "
                   f"{fmt(polls['last_ms_median'], '.1f')} ms (median); filtered in "
                   f"{polls['filtered_in']}")
    return '\n'.join(out)


#: The numeric options: flag, type, default, help.
OPTIONS: tuple[tuple[str, Callable[[str], Any], Any, str], ...] = (
    ('--hz', float, 100.0, 'publication rate'),
    ('--size', int, 1000, 'serialized message bytes'),
    ('--max-rate', float, 2.0, "the subscribers' max_rate"),
    ('--window', float, 20.0, 'part 1 seconds'),
    ('--counts', int_list, [1, 8, 32], 'part 2 subscriber counts'),
    ('--per-process', int, 8, 'part 2 subscribers (participants) per process'),
    ('--cpu-window', float, 10.0, 'part 2 seconds per phase'),
    ('--rounds', int, 100, 'part 3 polls'),
    ('--poll-n', int, 3, 'part 3 messages per poll'),
    ('--poll-settle', float, 0.3, 'part 3 seconds to wait for extra messages after each poll'),
    ('--warmup', float, 3.0, 'seconds after matching before a window starts'),
)


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    for flag, kind, default, text in OPTIONS:
        parser.add_argument(flag, type=kind, default=default, help=text)
    parser.add_argument('--parts', default='bytes,cpu,polls',
                        help='which parts to run, comma-separated')
    parser.add_argument('--output', type=Path, default=None,
                        help='results file (default: benchmarks/results/rate-<date>-<host>.json)')
    parser.add_argument('--markdown', type=Path, default=None, metavar='RESULTS',
                        help='run nothing: print the tables of a results file')
    return parser.parse_args(argv)


def main(argv: list[str]) -> int:
    """Run the three parts (or only present a results file) and print the tables."""
    args = parse_args(argv)
    if args.markdown:
        print(markdown(json.loads(args.markdown.read_text())))
        return 0
    begun = time.monotonic()
    date = datetime.date.today().isoformat()
    output = args.output or REPO / 'benchmarks' / 'results' / f'rate-{date}-{platform.node()}.json'
    results: dict[str, Any] = {
        'benchmark': 'rate',
        'command': ' '.join([Path(sys.executable).name, '-m', 'benchmarks.rate', *argv]),
        'date': datetime.datetime.now().astimezone().isoformat(timespec='seconds'),
        'machine': environment_facts(), 'niceness': os.nice(0),
        'args': {k: v for k, v in vars(args).items() if k not in ('output', 'markdown')},
        'network': 'rx_bytes of each client\'s own veth (network namespace per client process, '
                   'FASTDDS_BUILTIN_TRANSPORTS=UDPv4); publishers guarded'}

    def progress(line: str) -> None:
        print(f'[{time.monotonic() - begun:7.1f} s] {line}', flush=True)

    def save() -> None:
        results['elapsed_s'] = time.monotonic() - begun
        output.write_text(json.dumps(results, indent=1))

    parts = args.parts.split(',')
    topic = f'/cft_rate_{os.urandom(3).hex()}'
    try:
        # Each part in a topology and domain of its own: in one shared by two parts, the second
        # part's new publisher matched no subscriber within 60 s (whichever part came first).
        for part in ('bytes', 'cpu', 'polls'):
            if part not in parts:
                continue
            progress(f'part {part}')
            run = Run(args, progress)
            try:
                if part == 'polls':
                    results['polls'] = part_polls(run, topic + '_polled')
                else:
                    pub = run.start('publisher', 'publisher', topic, args.hz, args.size, 0,
                                    server=True)
                    if part == 'bytes':
                        results['bytes'] = part_bytes(run, pub, topic)
                        # The same subscriber alone on the writer: the side-by-side plain
                        # readers make the writer send it a GAP and a heartbeat per message.
                        progress('part bytes: max_rate alone')
                        alone = bytes_received(run, pub, topic, ('rate',))
                        ideal = results['bytes']['ideal_bytes_per_s']
                        mine = alone['kinds']['rate']
                        alone['rate_to_ideal'] = mine['rx_bytes_per_s'] / ideal
                        alone['rate_topic_to_ideal'] = mine['topic_bytes_per_s'] / ideal
                        results['bytes_alone'] = alone
                    else:
                        results['cpu'] = part_cpu(run, pub, topic)
            finally:
                run.close()
            save()
    finally:
        results['load_average_at_end'] = os.getloadavg()
        save()
        progress(f'results: {output}')
    print(markdown(results))
    return 0


if __name__ == '__main__':
    sys.exit(main_or_role(main, ROLES))
