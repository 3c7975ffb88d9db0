"""A load client process: one action client that sends goals on command and accounts what arrives.

Usage: ``python -m harness.client ACTION CONFIG GOALS ORDER DEPTH [INTERVAL_S]``

CONFIG is ``rclpy`` (plain :class:`rclpy.action.ActionClient`), ``client`` or ``goals``
(:class:`cft_action.ActionClient` in that mode), or ``upstream`` (the emulation of the upstream
design in :mod:`harness.upstream`). Every queue is DEPTH deep. With INTERVAL_S > 0 the goals of
``go`` are sent one every INTERVAL_S seconds instead of all at once (goals that arrive over time,
for the status topic's benchmark).

Before ``READY`` the client completes one goal of order 0 (no feedback): ``wait_for_server`` only
sees the server in the graph, while this round trip proves that the endpoints matched.

Commands on stdin, one per line:

- ``go``: send GOALS goals of ORDER feedback messages each, with a feedback callback each (at once,
  or one every INTERVAL_S).
- ``progress``: reply ``PROGRESS <json>`` with the counters so far.
- ``report``: reply ``RESULT <json>`` with everything measured since ``go``.
- ``goals``: reply ``GOALS <json>``: feedback callbacks per goal, by goal UUID in hex (the keys of
  ``harness.server``'s ``GOALS``), every goal sent included.
- ``quit`` (or end of input): exit.

What it counts, from ``go`` on:

- ``own`` and ``foreign``: feedback messages taken from rcl, split by whether the goal is one of
  this client's. They are counted in ``take_data``, below every filter, so a message that rmw or the
  writer filtered out is not counted and one that rclpy drops later is.
- ``callbacks``: feedback that reached a user callback, with ``latency_us`` from the server's
  publish time in the message to the callback.
- ``cpu_s``: user + system seconds of this process, all threads; ``thread_cpu_s``: the same by
  thread name (:func:`harness.procstat.thread_cpu_s`: Python's against Fast DDS's threads).
- ``status``, ``status_entries``, ``status_max_entries`` and ``status_cdr_bytes``: status messages
  (``GoalStatusArray``) taken from rcl, the goal entries they listed, the most in one, and their
  serialized size (:func:`status_array_size`; no headers). The status reader keeps the last sample
  only (rclpy's default QoS), so a client that falls behind takes fewer than the wire brought.
- ``goal_responses``: goal responses taken from rcl (rmw passes this client's only);
  ``terminal_listed``: this client's goals that the last status message taken lists as terminal.
  ``goals_done`` is rclpy's view instead (its goal handles' status, rejections included): rclpy
  sets a handle's status only from status messages taken after the goal's response, so a response
  that arrives after the goal's terminal status leaves the handle non-terminal for good.
- ``maxrss_kb`` and ``rss_kb``: this process's peak and current resident set.
- ``send_s``, ``last_response_s`` and ``last_callback_s``: seconds from ``go`` until every goal was
  sent, until the last goal response, and until the last feedback callback.
- ``status_samples_read`` and ``status_entries_listed`` (``client``/``goals``): status samples
  that the library's status trim read, and the goal entries they listed, most never converted to
  Python (``status_entries`` counts those that were).
- ``responses_dropped`` and ``responses_passed`` (``client``/``goals``): other clients' goal,
  cancel and result responses that the client's response readers dropped before Python, and the
  responses they passed (``response_filter_state``).
- ``updates``: filter changes (``client``/``goals``: ``feedback_filter_state.updates``;
  ``upstream``: every ``set_content_filter`` call, with ``recreations`` of the DataReader).

The client never asks for results: rclpy drops a goal's feedback callback as soon as its result
arrives, which would hide from the callbacks and the latency the own feedback still queued behind
the result in a client that cannot keep up. Goal completion comes from the status topic instead.
"""

from __future__ import annotations

import json
import os
import queue
import resource
import sys
import threading
import time
import uuid
from typing import Any, Callable, Optional

import rclpy
from action_msgs.msg import GoalStatus
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from test_msgs.action import Fibonacci
from unique_identifier_msgs.msg import UUID

from harness import procstat
from harness.status_model import status_array_size

CONFIGS = ('rclpy', 'client', 'goals', 'upstream')
#: Seconds before the probe goal, or its result request, is sent again.
PROBE_RESEND_S = 2.0

_TERMINAL = frozenset({GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED,
                       GoalStatus.STATUS_ABORTED})

#: The status counters of :class:`CountingMixin`, as :meth:`LoadClient.report` gives them.
STATUS_COUNTERS = ('status', 'status_entries', 'status_cdr_bytes')


def taken_feedback(data: dict) -> list[Any]:
    """The feedback messages in a ``take_data`` dictionary: rclpy's one, or the library's client's
    batch (``cft_action.action.client.MORE_FEEDBACK``)."""
    first = data.get('feedback')
    # Looked up, not imported: a process of plain rclpy clients does not load the library.
    library = sys.modules.get('cft_action.action.client')
    more = data.get(library.MORE_FEEDBACK, []) if library is not None else []
    return ([] if first is None else [first]) + list(more)


class CountingMixin:
    """Counts feedback taken from rcl, own and foreign, and status messages, in ``take_data``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """Set up the counters, then construct the action client with all arguments."""
        self.own_uuids: set[bytes] = set()
        self.own_taken = 0
        self.foreign_taken = 0
        self.status_counts = dict.fromkeys(STATUS_COUNTERS, 0)
        self.status_max_entries = 0
        self.goal_responses = 0
        self.last_status: Any = None
        super().__init__(*args, **kwargs)

    def take_data(self) -> dict:
        """Take as the base class does, and count the feedback or status message taken."""
        data = super().take_data()  # type: ignore[misc]  # the action client after it in the MRO
        for feedback in taken_feedback(data):
            if bytes(feedback.goal_id.uuid) in self.own_uuids:
                self.own_taken += 1
            else:
                self.foreign_taken += 1
        if data.get('goal') is not None:
            self.goal_responses += 1
        status = data.get('status')
        if status is not None:
            self.last_status = status
            entries = len(status.status_list)
            self.status_counts['status'] += 1
            self.status_counts['status_entries'] += entries
            self.status_counts['status_cdr_bytes'] += status_array_size(entries)
            self.status_max_entries = max(self.status_max_entries, entries)
        return data


def recording_feedback(base: type) -> type:
    """A subclass of ``base`` that records in ``feedback_taken`` (a list the caller sets) the goal
    UUID and the counter (``sequence[0]``) of every feedback message taken from rcl."""

    class Counting(base):
        def take_data(self) -> dict:
            data = super().take_data()
            for feedback in taken_feedback(data):
                self.feedback_taken.append((bytes(feedback.goal_id.uuid),
                                            int(feedback.feedback.sequence[0])
                                            if len(feedback.feedback.sequence) else -1))
            return data

    return Counting


def make_client(node: Node, config: str, action: str, qos: QoSProfile) -> Any:
    """Create the action client of ``config``, with the counting mixin on top."""
    if config == 'rclpy':
        from rclpy.action import ActionClient as base
        kwargs: dict[str, Any] = {}
    elif config == 'upstream':
        from harness.upstream import UpstreamEquivalentActionClient as base
        kwargs = {}
    elif config in ('client', 'goals'):
        from cft_action import ActionClient as base
        kwargs = {'feedback_filter': config}
    else:
        raise SystemExit(f'unknown configuration {config!r}; expected one of {CONFIGS}')
    counting = type(f'Counting{base.__name__}', (CountingMixin, base), {})
    return counting(node, Fibonacci, action, goal_service_qos_profile=qos,
                    result_service_qos_profile=qos, cancel_service_qos_profile=qos,
                    feedback_sub_qos_profile=qos, **kwargs)


def filter_counters(client: Any) -> dict[str, Any]:
    """The filter's counters, whatever the configuration; for cft_action, also the status trim's
    (the status samples it read and the goal entries they listed) and the response filter's."""
    state = getattr(client, 'feedback_filter_state', None)
    if state is not None:
        status, responses = client.goal_status_state, client.response_filter_state
        return {'updates': state.updates, 'active': state.active, 'reason': state.reason,
                'lib_taken': state.feedback_taken, 'lib_dropped': state.feedback_dropped,
                'status_samples_read': status.samples, 'status_entries_listed': status.entries,
                'responses_dropped': responses.dropped, 'responses_passed': responses.passed}
    if hasattr(client, 'filter_sets'):
        return {'updates': client.filter_sets, 'recreations': client.recreations,
                'active': not client.disabled_reason, 'reason': client.disabled_reason}
    return {'updates': 0, 'active': False, 'reason': 'plain rclpy'}


def cpu_seconds() -> float:
    """User + system seconds of this process, all threads."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def memory_kb() -> dict[str, int]:
    """This process's peak (``maxrss_kb``) and current (``rss_kb``) resident set, in kB."""
    return {'maxrss_kb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
            'rss_kb': procstat.rss_kb(os.getpid()) or 0}


class LoadClient:
    """Sends the goals and keeps the counters; everything runs in the executor's thread."""

    def __init__(self, node: Node, client: Any, goals: int, order: int,
                 interval_s: float = 0.0) -> None:
        self.node = node
        self.client = client
        self.goals = goals
        self.order = order
        self.interval_s = interval_s
        self.sent = 0
        self.timer: Any = None
        self.handles: list[Any] = []  # strong references: rclpy tracks status through weakrefs
        self.rejected = 0
        self.callbacks = 0
        self.misrouted = 0
        self.latency_us: list[int] = []
        self.per_goal: dict[bytes, int] = {}  # goal UUID -> feedback callbacks
        self.send_s: Optional[float] = None
        self.last_response_s: Optional[float] = None
        self.last_callback_s: Optional[float] = None
        self.terminal_s: Optional[float] = None  # when the status topic ended the last handle
        self.seen = (0, 0)  # status samples taken and goals rejected when note_terminal looked
        self.start_cpu = 0.0
        self.start_threads: dict[str, float] = {}
        self.start_counters: dict[str, Any] = {}
        self.start_status: dict[str, int] = {}
        self.start_goal_responses = 0
        self.started = 0.0

    def on_feedback_for(self, goal_uuid: bytes) -> Callable[[Any], None]:
        """The feedback callback of one goal: latency from the server's stamp, and routing."""
        def on_feedback(msg: Any) -> None:
            now = time.time_ns()
            sequence = msg.feedback.sequence
            self.latency_us.append((now - sequence[1] * 1_000_000_000 - sequence[2]) // 1000)
            self.callbacks += 1
            self.per_goal[goal_uuid] += 1
            self.last_callback_s = time.monotonic() - self.started
            if bytes(msg.goal_id.uuid) != goal_uuid:
                self.misrouted += 1
        return on_feedback

    def go(self, executor: SingleThreadedExecutor) -> None:
        """Send all goals, spinning in between so that responses do not pile up.

        With an interval, send the first now and the others from a timer, one per interval.
        """
        self.start_cpu = cpu_seconds()
        self.start_threads = procstat.thread_cpu_s(os.getpid())
        self.start_counters = filter_counters(self.client)
        self.start_status = dict(self.client.status_counts)
        self.start_goal_responses = self.client.goal_responses
        self.client.status_max_entries = 0
        self.started = time.monotonic()
        if self.interval_s > 0:
            self.send_one()
            self.timer = self.node.create_timer(self.interval_s, self.send_one)
            return
        for _ in range(self.goals):
            self.send_one()
            executor.spin_once(timeout_sec=0)
        self.send_s = time.monotonic() - self.started

    def send_one(self) -> None:
        """Send the next goal, with its feedback callback; stop the timer after the last."""
        if self.sent >= self.goals:
            if self.timer is not None:
                self.timer.cancel()
            return
        self.sent += 1
        new_uuid = getattr(self.client, 'new_goal_uuid', None)
        goal_uuid = new_uuid() if new_uuid else UUID(uuid=list(uuid.uuid4().bytes))
        key = bytes(goal_uuid.uuid)
        self.client.own_uuids.add(key)
        self.per_goal[key] = 0
        future = self.client.send_goal_async(
            Fibonacci.Goal(order=self.order), self.on_feedback_for(key), goal_uuid=goal_uuid)
        future.add_done_callback(self._on_goal_response)

    def _on_goal_response(self, future: Any) -> None:
        self.last_response_s = time.monotonic() - self.started
        handle = future.result()
        if handle.accepted:
            self.handles.append(handle)
        else:
            self.rejected += 1

    def goals_done(self) -> int:
        """Goals that reached a terminal status, or were rejected."""
        return self.rejected + sum(h.status in _TERMINAL for h in self.handles)

    def note_terminal(self) -> None:
        """Record when every goal handle first had a terminal status (called after each spin).

        A handle's status changes only when a status sample is taken (rclpy updates it in the same
        spin), and ``goals_done`` counts rejections too: the handles are counted only after a spin
        that took a sample or a rejection, so that a client of thousands of goals does not walk them
        at every feedback message."""
        seen = (self.client.status_counts['status'], self.rejected)
        if self.terminal_s is not None or not self.started or seen == self.seen:
            return
        self.seen = seen
        if self.goals_done() == self.goals:
            self.terminal_s = time.monotonic() - self.started

    def terminal_listed(self) -> int:
        """This client's goals that the last status message taken from rcl lists as terminal."""
        last = self.client.last_status
        return 0 if last is None else sum(
            entry.status in _TERMINAL and bytes(entry.goal_info.goal_id.uuid) in self.per_goal
            for entry in last.status_list)

    def progress(self) -> dict[str, Any]:
        """The counters that tell the orchestrator whether data is still arriving."""
        status = {k: v - self.start_status.get(k, 0) for k, v in self.client.status_counts.items()}
        return {'own': self.client.own_taken, 'foreign': self.client.foreign_taken,
                'callbacks': self.callbacks, 'goals_done': self.goals_done(),
                'goal_responses': self.client.goal_responses - self.start_goal_responses,
                'terminal_listed': self.terminal_listed(), **status}

    def report(self) -> dict[str, Any]:
        """Everything measured since ``go``."""
        counters = filter_counters(self.client)
        counters['updates_total'] = counters['updates']
        for key in ('updates', 'recreations', 'lib_taken', 'lib_dropped', 'status_samples_read',
                    'status_entries_listed'):
            if key in counters:
                counters[key] -= self.start_counters.get(key, 0)
        return {**self.progress(), 'goals': self.goals, 'order': self.order,
                'accepted': len(self.handles), 'rejected': self.rejected,
                'misrouted': self.misrouted, 'cpu_s': cpu_seconds() - self.start_cpu,
                'thread_cpu_s': {name: round(s - self.start_threads.get(name, 0.0), 3) for name, s
                                 in procstat.thread_cpu_s(os.getpid()).items()},
                'status_max_entries': self.client.status_max_entries,
                'send_s': self.send_s, 'last_response_s': self.last_response_s,
                'last_callback_s': self.last_callback_s, 'terminal_s': self.terminal_s,
                **memory_kb(),
                'latency_us': self.latency_us, **counters}

    def goal_counts(self) -> dict[str, int]:
        """Feedback callbacks per goal, by goal UUID in hex."""
        return {key.hex(): count for key, count in self.per_goal.items()}


def probe(node: Node, executor: SingleThreadedExecutor, client: Any, timeout: float) -> bool:
    """Complete one goal of order 0, which proves that all endpoints matched.

    The goal and its result request are resent every :data:`PROBE_RESEND_S`: a response written
    before the server's response writer matched this client's reader is lost for good (volatile),
    with plain rclpy too, so waiting longer for it would only time out.
    """
    deadline = time.monotonic() + timeout
    if not client.wait_for_server(timeout_sec=timeout):
        return False
    while time.monotonic() < deadline:
        future = client.send_goal_async(Fibonacci.Goal(order=0))
        executor.spin_until_future_complete(future, timeout_sec=PROBE_RESEND_S)
        if not future.done():
            continue
        while time.monotonic() < deadline:
            result = future.result().get_result_async()
            executor.spin_until_future_complete(result, timeout_sec=PROBE_RESEND_S)
            if result.done():
                return True
    return False


def read_commands(commands: queue.Queue, wake: Any) -> None:
    """Forward stdin lines to the executor's thread; end of input means ``quit``."""
    for line in sys.stdin:
        commands.put(line.strip())
        wake.trigger()
    commands.put('quit')
    wake.trigger()


def main() -> None:
    """Run one load client until ``quit``."""
    action, config = sys.argv[1], sys.argv[2]
    goals, order, depth = int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
    interval_s = float(sys.argv[6]) if len(sys.argv) > 6 else 0.0
    rclpy.init()
    node = Node(f'cft_load_client_{uuid.uuid4().hex[:8]}')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
    client = make_client(node, config, action, qos)
    if not probe(node, executor, client, timeout=60):
        print('NO SERVER', flush=True)
        return
    load = LoadClient(node, client, goals, order, interval_s)
    commands: queue.Queue[str] = queue.Queue()
    # A command wakes the executor through a guard condition, so the client sleeps while nothing
    # arrives: polling stdin between short spins cost 40 idle clients most of a core, which
    # showed in their CPU figures and slowed the server. Commands run here, between spins, since
    # ``go`` spins itself and spin_once must not be nested.
    wake = node.create_guard_condition(lambda: None)
    threading.Thread(target=read_commands, args=(commands, wake), daemon=True).start()
    print('READY', flush=True)
    running = True
    while running:
        executor.spin_once(timeout_sec=1.0)
        load.note_terminal()
        while not commands.empty():
            command = commands.get_nowait()
            if command == 'go':
                load.go(executor)
            elif command == 'progress':
                print('PROGRESS ' + json.dumps(load.progress()), flush=True)
            elif command == 'report':
                print('RESULT ' + json.dumps(load.report()), flush=True)
            elif command == 'goals':
                print('GOALS ' + json.dumps(load.goal_counts()), flush=True)
            elif command == 'quit':
                running = False
    client.destroy()
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
