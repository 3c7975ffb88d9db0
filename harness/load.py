"""The load harness shared by ``make demo`` and ``make bench``: processes, phases and accounting.

One run starts one action server (:mod:`harness.server`, under the server guard) and then, for
each configuration in turn, N fresh client processes (:mod:`harness.client`) that each send M
goals at once.
A phase goes:

1. start the clients; each proves with an order-0 goal that its endpoints matched (``READY``);
2. snapshot the server's counters and every client's network counters; ``go`` to all clients;
3. wait until the server has accepted and finished all N x M goals;
4. wait until no client's counters move any more (a client that cannot keep up is still taking its
   backlog), and at least :data:`SETTLE_S` (so that filter changes made after the goals finished,
   such as ``goals`` mode shrinking its filter, are counted);
5. snapshot the counters again, collect every client's ``RESULT`` and stop the clients.

Bytes are the ``rx_bytes`` of each client's own network interface when network namespaces can be
made (root, iproute2: see :mod:`harness.netns`); otherwise they are estimated as feedback messages
taken x the serialized size of one feedback message, and the result says so.

A spec may add *bystanders* (:attr:`LoadSpec.bystanders`): plain rclpy clients that run next to the
phase's clients in every phase, with the same goals, and are accounted apart (a dashboard that
receives every goal's feedback). A phase may also run fewer clients than the run's spec
(``run_phase(config, clients=K)``), so that one server serves phases of several sizes.
:class:`CapturingRun` breaks the first client process's received bytes down by kind, with a packet
capture (``harness/capture.py``, run as a child process in that client's namespace); the first
client process is the first bystander when there are any.
"""

from __future__ import annotations

import dataclasses
import os
import statistics
import time
from typing import Any, Callable, Optional, Sequence

from cft_action.action.client import FINISHED_GOAL_GRACE
from harness import netns
from harness.capture import CATEGORIES
from harness.domain import unused_domain
from harness.proc import Proc, pinned, python_module, stop_all
from harness.report import fmt, grid

#: The configurations, in the order they run; ``rclpy`` (plain) first, since ratios refer to it.
CONFIG_LABELS = {
    'rclpy': 'plain rclpy',
    'client': 'cft client mode',
    'goals': 'cft goals mode',
    'upstream': 'upstream-equivalent',
}

#: Seconds of quiet after the last goal finished before a phase is accounted: longer than
#: cft_action's FINISHED_GOAL_GRACE plus a release check, after which ``goals`` mode drops finished
#: goals' terms (an update that belongs to the phase).
SETTLE_S = FINISHED_GOAL_GRACE + 2.5

#: Seconds a finished goal stays on the server, unless a spec says otherwise. Every status message
#: lists all goals the server keeps, and goes to every client: with rclpy's default of 900 s each
#: phase of a run would carry the goals of all earlier phases, and later configurations would
#: receive more status bytes.
#: The load clients never ask for results, so nothing else depends on it.
RESULT_TIMEOUT_S = 2

#: Memory one client may spend on queued feedback; bounds the queue depth for large messages.
_QUEUE_BYTES = 256 * 1024 * 1024

#: Feedback sizes by name: int32 elements of padding after the 3-element header of every feedback
#: message, for 36 B (``small``), 1 kB, 4 kB and 10 kB messages (:func:`feedback_size`).
SIZES = {'small': 0, '1k': 250, '4k': 1000, '10k': 2500}

Progress = Callable[[str], None]


@dataclasses.dataclass
class LoadSpec:
    """One load point.

    :ivar clients: client processes (N).
    :ivar goals: goals each client sends at once (M).
    :ivar order: feedback messages per goal; a goal lasts ``order / rate_hz`` seconds.
    :ivar rate_hz: feedback rate per goal.
    :ivar pad: int32 elements added to each feedback message (0: small, 2500: 10 kB).
    :ivar network: ``'auto'`` (namespaces when possible), ``'netns'`` or ``'count'``.
    :ivar drain_timeout: seconds a phase may take after its goals finished, for slow clients.
    :ivar goals_timeout: seconds the goals of a phase may take; None: 120 + 30 x their nominal
        duration (a saturated machine runs them several times slower), plus the time their
        sending takes with ``goal_interval_s``.
    :ivar settle_s: seconds of quiet after the last goal before a phase is accounted (see
        :data:`SETTLE_S`).
    :ivar server_env: extra environment of the server process (e.g. the guard's settings).
    :ivar guarded: whether the server runs under the guard (``cft-action guard``).
    :ivar bystanders: plain rclpy client processes started first in every phase, next to the
        phase's N clients, with M goals each like them; they receive every goal's feedback. They
        are reported apart (``phase['bystanders']``, ``phase['bystander_summary']``) and are not
        part of the phase's per-client figures.
    :ivar result_timeout_s: seconds the server keeps a finished goal (and lists it in every status
        message); see :data:`RESULT_TIMEOUT_S`.
    :ivar goal_interval_s: 0: each client sends its goals at once on ``go``; else one every this
        many seconds.
    :ivar server_feedback_depth: the server's feedback writer alone keeps this many samples
        (rclpy's default is 10); None: as every queue (:func:`queue_depth`).
    :ivar loss_percent: with namespaces, the share of the server's packets that each client
        drops as they arrive (:meth:`harness.netns.Topology.add_client`); 0: none.
    :ivar server_cpus: the CPUs the server process may run on (``taskset -c`` syntax, e.g.
        ``'0'``); None: any.
    :ivar client_cpus: the same for every client process (bystanders included).
    """

    clients: int = 8
    goals: int = 4
    order: int = 1000
    rate_hz: float = 100.0
    pad: int = 0
    network: str = 'auto'
    drain_timeout: float = 300.0
    goals_timeout: Optional[float] = None
    settle_s: float = SETTLE_S
    server_env: dict[str, str] = dataclasses.field(default_factory=dict)
    guarded: bool = True
    bystanders: int = 0
    result_timeout_s: int = RESULT_TIMEOUT_S
    goal_interval_s: float = 0.0
    server_feedback_depth: Optional[int] = None
    loss_percent: float = 0.0
    server_cpus: Optional[str] = None
    client_cpus: Optional[str] = None

    @property
    def total_goals(self) -> int:
        """N x M: the goals of the phase's clients."""
        return self.clients * self.goals

    @property
    def all_goals(self) -> int:
        """(N + bystanders) x M: every goal the server serves in a phase."""
        return (self.clients + self.bystanders) * self.goals


def feedback_size(pad: int) -> int:
    """Serialized size (CDR, with its 4-byte header) of one feedback message with ``pad``."""
    from rclpy.serialization import serialize_message
    from test_msgs.action import Fibonacci
    message = Fibonacci.Impl.FeedbackMessage()
    message.feedback.sequence = [0] * (3 + pad)
    return len(serialize_message(message))


def queue_depth(spec: LoadSpec) -> int:
    """The depth of every queue, on both sides.

    rclpy's default of 10 drops goal requests, responses and feedback in bursts. A plain client may
    fall behind by all the feedback of a phase (it takes every client's), so its queue holds all of
    it, within :data:`_QUEUE_BYTES`: what overflows that is lost, and shows as own + foreign below
    what the server published.
    """
    everything = spec.all_goals * spec.order + 100
    return max(1000, min(everything, _QUEUE_BYTES // feedback_size(spec.pad)))


def wait_for_quiet(clients: Sequence[Proc], since: float, settle_s: float, drain_timeout: float,
                   progress: Progress = print) -> None:
    """Wait until no client's ``PROGRESS`` moves for 1.5 s, and ``settle_s`` after ``since``.

    A client that cannot keep up is still taking its backlog after the server finished. Gives up,
    and says so, after ``drain_timeout`` seconds.
    """
    deadline = time.monotonic() + drain_timeout
    last: Optional[list[dict[str, Any]]] = None
    stable_since = time.monotonic()
    shown = time.monotonic()
    while True:
        now = [c.request_json('progress', 'PROGRESS') for c in clients]
        t = time.monotonic()
        if now != last:
            last, stable_since = now, t
        if t - stable_since >= 1.5 and t - since >= settle_s:
            return
        if t > deadline:
            progress(f'    drain timeout after {drain_timeout:.0f} s; accounting what arrived')
            return
        if t - shown >= 3:
            shown = t
            taken = sum(p['own'] + p['foreign'] for p in now)
            progress(f'    clients still taking feedback: {taken} taken so far')
        time.sleep(0.5)


# --- processes ------------------------------------------------------------------------------------

# --- a run ----------------------------------------------------------------------------------------

class LoadRun:
    """One server process and its network, shared by the phases of one load point."""

    def __init__(self, spec: LoadSpec, progress: Progress = print) -> None:
        """Start the server (guarded), in its own namespace when bytes are counted on the wire."""
        from cft_action import guard
        self.spec = spec
        self.progress = progress
        self.action = f'/cft_load_{os.urandom(4).hex()}'
        self.depth = queue_depth(spec)
        self.topology: Optional[netns.Topology] = None
        self.network_note = ''
        reason = netns.unavailable_reason() if spec.network in ('auto', 'netns') else \
            'network counting not requested'
        if reason is not None and spec.network == 'netns':
            raise RuntimeError(f'network namespaces are not available: {reason}')
        self.env = dict(os.environ)
        self.env['ROS_DOMAIN_ID'] = os.environ.get('CFT_LOAD_DOMAIN_ID') or str(unused_domain())
        self.env.pop('CFT_ACTION_FEEDBACK_FILTER', None)  # each phase sets its own mode
        if reason is None:
            netns.remove_stale()
            self.topology = netns.Topology()
            self.env.update(netns.ENVIRONMENT)
            self.bytes_method = 'netns'
            self.network_note = ('bytes: rx_bytes of each client\'s own veth interface (network '
                                 'namespace per client, FASTDDS_BUILTIN_TRANSPORTS=UDPv4)')
        else:
            self.env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
            self.bytes_method = 'estimated'
            self.network_note = (f'bytes ESTIMATED as feedback messages taken x serialized size '
                                 f'({feedback_size(spec.pad)} B), no headers, status or discovery: '
                                 f'no network namespaces ({reason})')
        argv = python_module('harness.server', self.action, 1.0 / spec.rate_hz, '--pad', spec.pad,
                             '--depth', self.depth, '--result-timeout', spec.result_timeout_s)
        if spec.server_feedback_depth is not None:
            argv += ['--feedback-depth', str(spec.server_feedback_depth)]
        if self.topology:
            argv = self.topology.command(self.topology.server, argv)
        argv = pinned(spec.server_cpus, argv)
        server_env = {**self.env, **spec.server_env}
        self.server = Proc('server', argv,
                           guard.environment(server_env) if spec.guarded else server_env)
        try:
            self.server.expect('READY', 60)
        except Exception:
            self.close()
            raise

    def server_stats(self) -> dict[str, Any]:
        """The server's counters."""
        return self.server.request_json('stats', 'STATS')

    def close(self) -> None:
        """Stop the server and delete the namespaces."""
        self.server.stop()
        if self.topology:
            self.topology.close()

    # --- one phase ----------------------------------------------------------------------------

    def window_started(self, clients: list[Proc], server_stats: dict[str, Any]) -> None:
        """Hook: the clients are ready and ``go`` comes next. For subclasses that observe."""

    def window_ended(self, clients: list[Proc]) -> dict[str, Any]:
        """Hook: the measured window is over; return entries to add to the phase's figures."""
        return {}

    def _start_clients(self, config: str) -> list[Proc]:
        """The bystanders (plain rclpy) first, then the phase's clients of ``config``."""
        spec = self.spec
        roles = [('rclpy', f'bystander {i}') for i in range(spec.bystanders)]
        roles += [(config, f'{config} client {i}') for i in range(spec.clients)]
        clients = []
        for role, name in roles:
            argv = python_module('harness.client', self.action, role, spec.goals, spec.order,
                                 self.depth, spec.goal_interval_s)
            if self.topology:
                argv = self.topology.command(self.topology.add_client(spec.loss_percent), argv)
            clients.append(Proc(name, pinned(spec.client_cpus, argv), self.env))
        return clients

    def _network(self, clients: list[Proc]) -> list[Optional[dict[str, int]]]:
        if not self.topology:
            return [None] * len(clients)
        return [netns.interface_counters(c.pid) for c in clients]

    def _wait_for_goals(self, before: dict[str, Any]) -> dict[str, Any]:
        """Wait until the server accepted and finished every goal of the phase."""
        spec = self.spec
        expected = spec.all_goals * spec.order
        timeout = spec.goals_timeout or (120 + 30 * spec.order / spec.rate_hz
                                         + spec.goals * spec.goal_interval_s)
        deadline = time.monotonic() + timeout
        shown = 0.0
        while True:
            stats = self.server_stats()
            published = stats['published'] - before['published']
            accepted = stats['accepted'] - before['accepted']
            if accepted >= spec.all_goals and stats['active'] == 0:
                return stats
            if time.monotonic() > deadline:
                raise RuntimeError(f'goals did not finish within {timeout:.0f} s: '
                                   f'{accepted}/{spec.all_goals} accepted, '
                                   f'{published}/{expected} feedback published')
            if time.monotonic() - shown >= 2:
                shown = time.monotonic()
                self.progress(f'    server: {accepted}/{spec.all_goals} goals accepted, '
                              f'{published}/{expected} feedback published')
            time.sleep(0.25)

    def _wait_for_quiet(self, clients: list[Proc], since: float) -> None:
        """Wait until the clients' counters stop moving, at least SETTLE_S after ``since``."""
        wait_for_quiet(clients, since, self.spec.settle_s, self.spec.drain_timeout, self.progress)

    def run_phase(self, config: str, clients: Optional[int] = None) -> dict[str, Any]:
        """Run one configuration under this load; return its raw figures and summary.

        :param clients: the phase's client processes, at most the run's N (which sized the
            queues); None: N. While the phase runs, ``self.spec`` is the phase's spec.
        """
        if clients is None or clients == self.spec.clients:
            return self._run_phase(config)
        if not 0 <= clients <= self.spec.clients:
            raise ValueError(f'a phase may run 0 to {self.spec.clients} clients, not {clients}')
        run_spec = self.spec
        self.spec = dataclasses.replace(run_spec, clients=clients)
        try:
            return self._run_phase(config)
        finally:
            self.spec = run_spec

    def _label(self, config: str) -> str:
        spec = self.spec
        label = f'{CONFIG_LABELS[config]} x {spec.clients}'
        return label + (f' + {spec.bystanders} bystander' if spec.bystanders else '')

    def _run_phase(self, config: str) -> dict[str, Any]:
        spec = self.spec
        label = self._label(config)
        processes = spec.clients + spec.bystanders
        self.progress(f'[{label}] starting {processes} client processes')
        started = time.monotonic()
        clients = self._start_clients(config)
        try:
            for client in clients:
                client.expect('READY', 120 + 2 * processes)
            ready_s = time.monotonic() - started
            self.progress(f'[{label}] {processes} clients matched in '
                          f'{ready_s:.1f} s; sending {spec.goals} goals each, {spec.order} '
                          f'feedback per goal at {spec.rate_hz:g} Hz')
            before = self.server_stats()
            self.window_started(clients, before)
            net_before = self._network(clients)
            go = time.monotonic()
            for client in clients:
                client.send('go')
            done = self._wait_for_goals(before)
            goals_s = time.monotonic() - go
            self.progress(f'[{label}] goals finished in {goals_s:.1f} s; '
                          'waiting for the clients to take the rest')
            self._wait_for_quiet(clients, time.monotonic())
            window_s = time.monotonic() - go
            net_after = self._network(clients)
            extra = self.window_ended(clients)
            after = self.server_stats()
            reports = [c.request_json('report', 'RESULT') for c in clients]
        finally:
            stop_all(clients)
            if self.topology:
                # The namespaces of this phase's clients go with them; new ones come next phase.
                self.topology.close_clients()
        if self.server.poll() is not None:
            raise RuntimeError(f'the server died\n{self.server.tail()}')
        for report, client, b, a in zip(reports, clients, net_before, net_after):
            report['cpu_lifetime_s'] = client.cpu_lifetime_s
            if b is not None and a is not None:
                report.update({k: a[k] - b[k] for k in a})
        phase = {
            'config': config,
            'guarded': self.spec.guarded,
            'published': after['published'] - before['published'],
            'accepted': after['accepted'] - before['accepted'],
            'server_cpu_s': after['cpu_s'] - before['cpu_s'],
            'server_cpu_goals_s': done['cpu_s'] - before['cpu_s'],
            # its system (kernel) share: sending, and waking the threads that receive
            'server_sys_goals_s': done['sys_s'] - before['sys_s'] if 'sys_s' in done else None,
            'published_at_goals': done['published'] - before['published'],
            # the server's context switches (harness.server's stats), go to its last goal
            'server_switches_goals': {k: done[k] - before[k] for k in ('switches', 'preempted')
                                      if k in done},
            # requests the server took from go to its last goal (an arrival probe's are cancels)
            'server_requests_goals': {k: done[k] - before[k]
                                      for k in ('goal_requests', 'cancel_requests') if k in done},
            'timed_out': done.get('timed_out', False),
            **{key: {k: v - before.get(key, {}).get(k, 0) for k, v in after.get(key, {}).items()}
               for key in ('guard_filter', 'guard_heartbeats', 'guard_status')},
            'late_ticks': after['late_ticks'] - before['late_ticks'],
            'intervals': after['intervals'] - before['intervals'],
            'interval_s': after['interval_s'] - before['interval_s'],
            'guard': after.get('guard', ''),
            'ready_s': ready_s, 'goals_s': goals_s, 'window_s': window_s,
            'n_clients': spec.clients,
            'clients': reports[spec.bystanders:],
            **extra,
        }
        phase['summary'] = summarize(phase, spec, self.bytes_method)
        if spec.bystanders:
            phase['bystanders'] = reports[:spec.bystanders]
            phase['bystander_summary'] = client_figures(phase['bystanders'], spec,
                                                        self.bytes_method)
        time.sleep(1.0)  # let discovery retire this phase's readers before the next one matches
        return phase


class CapturingRun(LoadRun):
    """A load run that captures the first client process's received frames in every phase.

    ``harness/capture.py`` runs in that client's namespace from :meth:`window_started` to
    :meth:`window_ended`, and the phase gets its ``anatomy``: bytes, packets and samples by kind
    (feedback data, feedback gap/heartbeat, status, discovery, other). The first client process is
    the first bystander when the spec has any, else the first of the phase's clients. Capturing
    costs CPU on the machine being measured, so a run with it is a run of its own.
    """

    def window_started(self, clients: list[Proc], server_stats: dict[str, Any]) -> None:
        """Start the capture on the first client's interface, before ``go``, once it listens."""
        if not self.topology:
            raise RuntimeError('a packet capture needs network namespaces (root and iproute2)')
        writers = server_stats['writers']
        argv = python_module('harness.capture', netns.INTERFACE,
                             ','.join(writers['feedback']), ','.join(writers['status']))
        self._capture = Proc('capture', self.topology.command(self.topology.clients[0], argv),
                             self.env)
        self._capture.expect('SNIFFING', 30)

    def window_ended(self, clients: list[Proc]) -> dict[str, Any]:
        """Stop the capture; its counts by kind are the phase's ``anatomy``."""
        anatomy = self._capture.request_json('stop', 'RESULT', timeout=30)
        self._capture.stop()
        return {'anatomy': anatomy}


# --- accounting -----------------------------------------------------------------------------------

def percentile(values: Sequence[float], q: float) -> Optional[float]:
    """The ``q``-quantile (0..1) of ``values`` by nearest rank, or None when empty."""
    if not values:
        return None
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, round(q * len(ordered)) - 1))]


def _mean(values: Sequence[float]) -> Optional[float]:
    return statistics.fmean(values) if values else None


def client_figures(clients: list[dict[str, Any]], spec: LoadSpec,
                   bytes_method: str) -> dict[str, Any]:
    """Per-client means and totals of the reports ``clients``; moves their latency samples into
    percentiles. With no clients, the means are None."""
    size = feedback_size(spec.pad)
    latencies = [v for c in clients for v in c.pop('latency_us')]
    for c in clients:
        c['est_bytes'] = (c['own'] + c['foreign']) * size
    byte_key = 'rx_bytes' if bytes_method == 'netns' else 'est_bytes'
    own_mean = _mean([c['own'] for c in clients])
    bytes_per_client = [c[byte_key] for c in clients]
    return {
        'own_per_client': own_mean,
        'foreign_per_client': _mean([c['foreign'] for c in clients]),
        'expected_own_per_client': spec.goals * spec.order,
        'callbacks_per_client': _mean([c['callbacks'] for c in clients]),
        'misrouted': sum(c['misrouted'] for c in clients),
        'bytes_method': bytes_method,
        'bytes_per_client': _mean(bytes_per_client),
        'bytes_per_client_min': min(bytes_per_client, default=None),
        'bytes_per_client_max': max(bytes_per_client, default=None),
        'own_feedback_bytes_per_client': None if own_mean is None else own_mean * size,
        'feedback_message_bytes': size,
        'client_cpu_s': sum(c['cpu_s'] for c in clients),
        'client_cpu_s_per_client': _mean([c['cpu_s'] for c in clients]),
        'latency_samples': len(latencies),
        'latency_p50_ms': _ms(percentile(latencies, 0.50)),
        'latency_p90_ms': _ms(percentile(latencies, 0.90)),
        'latency_p99_ms': _ms(percentile(latencies, 0.99)),
        'latency_max_ms': _ms(max(latencies) if latencies else None),
        # Status messages taken from rcl (not those the keep-last-1 reader dropped unread).
        'status_per_client': _mean([c.get('status', 0) for c in clients]),
        'status_entries_per_client': _mean([c.get('status_entries', 0) for c in clients]),
        'status_cdr_bytes_per_client': _mean([c.get('status_cdr_bytes', 0) for c in clients]),
        'status_max_entries': max((c.get('status_max_entries', 0) for c in clients), default=0),
    }


def summarize(phase: dict[str, Any], spec: LoadSpec, bytes_method: str) -> dict[str, Any]:
    """The phase's clients' figures (:func:`client_figures`) and the server's side of it."""
    clients = phase['clients']
    updates = sum(c['updates'] for c in clients)
    return {
        **client_figures(clients, spec, bytes_method),
        'all_feedback': phase['published'],
        'server_cpu_s': phase['server_cpu_s'],
        # The server's side, from go until its last goal finished: what its publishing achieved.
        'server_msgs_per_s': (phase['published_at_goals'] / phase['goals_s']
                              if phase['goals_s'] else None),
        'server_cpu_ms_per_msg': (1000 * phase['server_cpu_goals_s'] / phase['published_at_goals']
                                  if phase['published_at_goals'] else None),
        'updates': updates,
        'updates_per_goal': updates / spec.total_goals if spec.total_goals else None,
        'recreations': sum(c.get('recreations', 0) for c in clients),
        'filters_disabled': sum(1 for c in clients
                                if phase['config'] == 'upstream' and not c['active']),
        # Feedback per second per goal, first to last: below rate_hz when the server could not
        # keep the rate (late_ticks counts that).
        'achieved_rate_hz': (phase['intervals'] / phase['interval_s']
                             if phase['interval_s'] else None),
        'late_ticks': phase['late_ticks'],
    }


def bystander_figures(phase: dict[str, Any]) -> dict[str, Any]:
    """What the first bystander of ``phase`` received, per feedback sample it took; with
    :class:`CapturingRun`, also by kind (``per_sample``)."""
    report = phase['bystanders'][0]
    samples = report['own'] + report['foreign']
    figures: dict[str, Any] = {
        'neighbours': phase['n_clients'],
        'neighbour_config': phase['config'] if phase['n_clients'] else None,
        'published': phase['published'],
        'samples': samples,
        'lost': phase['published'] - samples,
        'rx_bytes': report.get('rx_bytes'),
        'rx_packets': report.get('rx_packets'),
        'rx_bytes_per_sample': report['rx_bytes'] / samples if samples and 'rx_bytes' in report
        else None,
        'packets_per_sample': report['rx_packets'] / samples if samples and 'rx_packets' in report
        else None,
        'feedback_message_bytes': phase['summary']['feedback_message_bytes'],
        'latency_p50_ms': phase['bystander_summary']['latency_p50_ms'],
        'latency_p99_ms': phase['bystander_summary']['latency_p99_ms'],
        'neighbour_rx_bytes_per_client': phase['summary']['bytes_per_client'],
        'load_average_at_end': phase.get('load_average_at_end'),
    }
    anatomy = phase.get('anatomy')
    if anatomy and samples:
        figures['per_sample'] = {c: anatomy[c]['bytes'] / samples for c in CATEGORIES}
        data = anatomy['feedback data']
        figures['feedback_data_bytes_per_packet'] = (data['bytes'] / data['packets']
                                                     if data['packets'] else None)
    return figures


def _ms(us: Optional[float]) -> Optional[float]:
    return None if us is None else us / 1000.0


def add_ratios(phases: list[dict[str, Any]]) -> None:
    """Add ``bytes_to_own_feedback`` to every summary, and ``ratio_to_plain`` when a plain rclpy
    phase is among ``phases``."""
    for phase in phases:
        s = phase['summary']
        s['bytes_to_own_feedback'] = (s['bytes_per_client'] / s['own_feedback_bytes_per_client']
                                      if s['own_feedback_bytes_per_client'] else None)
    plain = next((p['summary'] for p in phases if p['config'] == 'rclpy'), None)
    if plain is None:
        return
    keys = {'foreign': 'foreign_per_client', 'bytes': 'bytes_per_client',
            'cpu': 'client_cpu_s', 'p50': 'latency_p50_ms', 'p99': 'latency_p99_ms',
            'server_rate': 'server_msgs_per_s', 'server_cpu': 'server_cpu_ms_per_msg'}
    for phase in phases:
        s = phase['summary']
        s['ratio_to_plain'] = {name: (s[k] / plain[k] if s[k] is not None and plain[k] else None)
                               for name, k in keys.items()}


def round_order(configs: Sequence[str], rounds: int) -> list[tuple[int, str]]:
    """(round, configuration) in the order they run: ``configs`` in odd rounds, reversed in even
    ones (plain, cft, cft, plain, ...), so that a drift of the machine's load over a run weighs on
    every configuration alike."""
    return [(r + 1, c) for r in range(rounds) for c in (configs if r % 2 == 0 else configs[::-1])]


def pool_phases(phases: list[dict[str, Any]]) -> dict[str, Any]:
    """Several phases of one configuration against one server, as one phase: the server's rate,
    CPU per message and achieved rate over all of them (its counters added up), every other figure
    of the summary the mean of the phases' (of each phase's percentiles, too)."""
    summaries = [p['summary'] for p in phases]
    summary: dict[str, Any] = {}
    for key, first in summaries[0].items():
        values = [s[key] for s in summaries]
        numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
        mean = statistics.fmean(values) if numeric else first
        # counts stay counts where their mean is whole (filter updates: 0 and 0 are 0, not 0.0)
        whole = all(isinstance(v, int) for v in values) and float(mean).is_integer()
        summary[key] = int(mean) if numeric and whole else mean
    total = {k: sum(p[k] for p in phases)
             for k in ('published_at_goals', 'goals_s', 'server_cpu_goals_s', 'intervals',
                       'interval_s')}
    summary['server_msgs_per_s'] = (total['published_at_goals'] / total['goals_s']
                                    if total['goals_s'] else None)
    summary['server_cpu_ms_per_msg'] = (1000 * total['server_cpu_goals_s']
                                        / total['published_at_goals']
                                        if total['published_at_goals'] else None)
    summary['achieved_rate_hz'] = (total['intervals'] / total['interval_s']
                                   if total['interval_s'] else None)
    return {**phases[0], **total, 'summary': summary, 'pooled_phases': len(phases)}


def run_load(spec: LoadSpec, configs: Sequence[str], progress: Progress = print,
             run_class: type['LoadRun'] = LoadRun, rounds: int = 1) -> dict[str, Any]:
    """Run ``configs`` under the load ``spec`` against one server, ``rounds`` times
    (:func:`round_order`). With several rounds, ``phases`` holds one phase per configuration,
    pooled over its rounds (:func:`pool_phases`), and ``round_phases`` every phase as it ran."""
    run = run_class(spec, progress)
    try:
        progress(f'server ready ({run.network_note})')
        ran = [run.run_phase(config) for _, config in round_order(configs, rounds)]
    finally:
        run.close()
    phases = ran if rounds == 1 else [pool_phases([p for p in ran if p['config'] == c])
                                      for c in configs]
    add_ratios(phases)
    result = {'spec': dataclasses.asdict(spec), 'queue_depth': run.depth,
              'bytes_method': run.bytes_method, 'network_note': run.network_note,
              'domain_id': run.env['ROS_DOMAIN_ID'], 'phases': phases}
    if rounds > 1:
        result['round_phases'] = ran
    return result


# --- presentation ---------------------------------------------------------------------------------

def phase_label(phase: dict[str, Any]) -> str:
    """The label of ``phase``'s configuration, and of its server when it ran without the guard."""
    label = CONFIG_LABELS[phase['config']]
    return label if phase.get('guarded', True) else f'{label}, unguarded server'


def format_table(result: dict[str, Any]) -> str:
    """The per-configuration table: absolute figures, then ratios to plain rclpy."""
    spec = result['spec']
    rows = [('configuration', 'own/cl', 'foreign/cl', 'kB rx/cl', 'rx/own', 'CPU s',
             'updates', 'upd/goal', 'p50 ms', 'p99 ms', 'rate Hz', 'srv msg/s', 'srv ms/msg')]
    for phase in result['phases']:
        s = phase['summary']
        rows.append((phase_label(phase), fmt(s['own_per_client']),
                     fmt(s['foreign_per_client']), fmt(s['bytes_per_client'] / 1000, '.1f'),
                     fmt(s.get('bytes_to_own_feedback'), '.2f'), fmt(s['client_cpu_s'], '.2f'),
                     str(s['updates']), fmt(s['updates_per_goal'], '.2f'),
                     fmt(s['latency_p50_ms'], '.2f'), fmt(s['latency_p99_ms'], '.2f'),
                     fmt(s['achieved_rate_hz'], '.0f'), fmt(s['server_msgs_per_s'], '.0f'),
                     fmt(s['server_cpu_ms_per_msg'], '.3f')))
    ratio_rows: list[tuple[str, ...]] = [('ratio to plain', 'foreign', 'bytes', 'CPU', 'p50',
                                          'p99', 'srv msg/s', 'srv ms/msg')]
    for phase in result['phases']:
        r = phase['summary'].get('ratio_to_plain')
        if r:
            ratio_rows.append((phase_label(phase), *(
                fmt(r[k], '.3f') for k in ('foreign', 'bytes', 'cpu', 'p50', 'p99',
                                            'server_rate', 'server_cpu'))))
    first = result['phases'][0]['summary']
    header = (f"N = {spec['clients']} clients x M = {spec['goals']} goals, {spec['order']} "
              f"feedback per goal at {spec['rate_hz']:g} Hz, {first['feedback_message_bytes']} B "
              f"per feedback message; all feedback per phase: {first['all_feedback']}; "
              f"own feedback expected per client: {first['expected_own_per_client']}")
    notes = [f"note: {result['network_note']}",
             'note: CPU s = user + system seconds of all client processes, from go to the end of '
             'the phase; latency from the server\'s publish to the user callback; rate Hz = '
             'feedback per second per goal that the server achieved; srv msg/s and srv ms/msg = '
             'feedback the server published per second, and its CPU milliseconds per message, '
             'from go until its last goal finished']
    pooled = [p for p in result['phases'] if p.get('pooled_phases', 1) > 1]
    if pooled:
        notes.append(f"note: {', '.join(phase_label(p) for p in pooled)}: "
                     f"{pooled[0]['pooled_phases']} phases each against one server, alternating, "
                     'pooled (the server\'s figures over all of them, the others their mean); '
                     'ratios to the plain rclpy phases of the same server')
    return '\n'.join([header, grid(rows), '', grid(ratio_rows), *notes])
