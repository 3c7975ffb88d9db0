# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The Fibonacci action server of every demo, benchmark and test, in a process of its own.

Usage: ``python -m harness.server ACTION PERIOD_S [--pad N] [--result-pad N] [--depth N|all]
[--result-timeout S] [--stats-every S] [--late-feedback S] [--executor single|multi]
[--goal-depth N] [--hold-goals N] [--record-readers] [--mute-cancel]``

Goal ``order`` is the number of feedback messages the goal gets (a negative order is rejected;
cancels are accepted). Each feedback ``sequence`` is ``[k, seconds, nanoseconds] + [0] * PAD``:
the message's index in its goal, then its publish time from ``time.time_ns()``, so that a client
on the same host can compute the latency from publish to its callback. The first feedback of a
goal is published in the first line of ``execute`` (as a real server that reports progress at
once), the others by a ticker thread every PERIOD_S, on an absolute schedule so that the rate stays
put when a tick takes long. The result's ``sequence`` is ``[feedback messages published for the
goal]``, so that a client can count what it lost, canceled goals included; ``--result-pad N``
appends N zeros to it (a large result: 25000 for 100 kB). With
``--late-feedback S``, a goal that succeeded gets one more feedback message (``k = order``) S
seconds after its result, the way a sample lost on the way and resent arrives at a client.
With ``--hold-goals N``, goals of positive order get their first feedback at once and then wait,
with no further feedback, until N of them have been accepted (or the command ``release`` comes):
so that N goals are live at once, however long their requests take to arrive.
With ``--mute-cancel``, cancel requests are taken and never answered, as by a broken server, or one
whose replies rmw keeps dropping.

Execute callbacks are coroutines, so one single-threaded executor serves any number of goals
(rclpy's ActionServer dropped goal requests under a MultiThreadedExecutor here).
``--executor multi`` spins a ``MultiThreadedExecutor`` instead, as many real servers do.

Queues: ``--depth N`` makes every queue keep-last N, reliable; ``--depth all`` keep-all (with a
1000-sample resource hint), which tests use so that nothing is dropped on a loaded machine; without
``--depth``, rclpy's defaults (keep-last 10), as an ordinary server has. ``--goal-depth N`` makes
the goal service alone keep-last N, reliable, and ``--feedback-depth N`` the feedback writer alone
(rclpy's default is 10: a writer whose history is full heartbeats every reader at each write).

Lines it prints: ``STATUS <guard active> <guard status>`` and ``READY`` at start; ``STATS <json>``
in reply to the command ``stats`` on stdin, and every ``--stats-every`` seconds if given (a crash
watcher then has the counters from just before a crash). The JSON holds ``t`` (monotonic seconds),
``published`` (feedback messages), ``accepted`` (goals), ``active`` (goals still running),
``late_ticks`` (ticks that started more than a period late: the server could not keep the rate),
``peak_active`` (the most goals running at once), ``held_accepted`` (goals of positive order
accepted), ``released`` (seconds from the start of the server until ``--hold-goals`` let the goals
go, or null), ``release_reason``, ``maxrss_kb`` (this process's peak resident set),
``goal_requests``, ``goal_responses`` and ``goal_response_errors`` (goal requests taken from rcl,
goal responses sent, and sends that failed: rclpy logs those and drops the goal, or that rmw
dropped because the client's response reader was not matched within 100 ms, which rclpy only
warns of while the goal runs), ``cancel_requests`` (cancel requests taken),
``intervals`` and ``interval_s`` (feedback intervals of finished goals and the seconds they took),
``cpu_s`` (user + system seconds of this process so far; ``sys_s``: the system seconds alone),
``switches`` and ``preempted`` (its threads' voluntary and involuntary context switches so far:
waits, and preemptions), ``guard``
(the server guard's status line), ``guard_calls``, ``guard_filter``, ``guard_writers`` and
``guard_filter_class`` (its call, filter-verdict, writer-limit and filter-class counters),
``guard_replies`` (its reply filter's), ``guard_prefilter`` (its Fast DDS 3 layer's state,
:func:`cft_action.guard.prefilter`), ``guard_feedback`` (its Fast DDS 3 feedback verdicts) and
``writers`` (the GUIDs of the feedback and status writers, and of the ``send_goal``,
``cancel_goal`` and ``get_result`` reply writers, in hex).
``GOALS <json>`` replies to the command ``goals``: the feedback messages published per goal so far,
by goal UUID in hex (``k`` runs 0, 1, ... in a goal, so that is all of them). ``READERS <json>``
replies to ``readers``: with ``--record-readers``, per goal UUID in hex, the GIDs (hex) of the
feedback readers in this server's graph when it took the goal's request (a graph query per goal,
2 ms with 40 readers: off by default, so as not to load the server that other benchmarks
measure); ``READERS_NOW <json>`` to ``readers now``, those in its graph now. The command
``release`` ends ``--hold-goals``; ``hold`` holds the goals that start from then on until the
next ``release``, as ``--hold-goals`` does. End of input stops the server.
"""

from __future__ import annotations

import argparse
import array
import json
import resource
import sys
import threading
import time
import warnings
from typing import Any, Optional

import rclpy
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import Executor, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from test_msgs.action import Fibonacci

from cft_action import guard
from harness.ros import leave_spinning_process

#: Index of the first padding element in a feedback ``sequence``.
HEADER = 3

#: rclpy's default: finished goals (and their results) stay on the server for 15 minutes.
DEFAULT_RESULT_TIMEOUT_S = 900


def queue_kwargs(depth: Optional[str], side: str = 'pub') -> dict[str, QoSProfile]:
    """The QoS arguments for ``--depth``: {} (rclpy's defaults) when None.

    ``side`` is ``'pub'`` for an ActionServer, ``'sub'`` for an ActionClient (its feedback queue).
    """
    if depth is None:
        return {}
    if depth == 'all':
        profile = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000,
                             reliability=ReliabilityPolicy.RELIABLE)
    else:
        profile = QoSProfile(depth=int(depth), reliability=ReliabilityPolicy.RELIABLE)
    names = ('goal_service_qos_profile', 'result_service_qos_profile',
             'cancel_service_qos_profile', f'feedback_{side}_qos_profile')
    return {name: profile for name in names}


#: The warning with which rclpy's ActionServer drops a goal whose response it could not send.
_SEND_FAILED = 'Failed to send goal response'
#: rclpy's RuntimeWarning when rmw_fastrtps dropped a response because the client's response reader
#: was not matched within the writer's max_blocking_time (100 ms): the client never gets it.
_RESPONSE_TIMED_OUT = 'failed to send response (timeout)'


def feedback_reader_gids(node: Node, topic: str, node_name: Optional[str] = None) -> list[str]:
    """The GIDs (hex, 16 bytes) of the readers on ``topic`` in ``node``'s graph, of one node if
    ``node_name`` is given."""
    return [bytes(info.endpoint_gid[:16]).hex()
            for info in node.get_subscriptions_info_by_topic(topic)
            if node_name is None or info.node_name == node_name]


class _CountingLogger:
    """An rclpy logger that counts the ActionServer's failed goal-response sends."""

    def __init__(self, logger: Any, on_failed: Any) -> None:
        self._logger = logger
        self._on_failed = on_failed

    def warn(self, message: str, *args: Any, **kwargs: Any) -> Any:
        if str(message).startswith(_SEND_FAILED):
            self._on_failed()
        return self._logger.warn(message, *args, **kwargs)

    warning = warn

    def __getattr__(self, name: str) -> Any:
        return getattr(self._logger, name)


class CountingActionServer(ActionServer):
    """An rclpy ActionServer that records, per goal UUID, whether its goal response went out."""

    def __init__(self, *args: Any, record_readers: bool = False, mute_cancel: bool = False,
                 **kwargs: Any) -> None:
        self.request_lock = threading.Lock()
        self.record_readers = record_readers
        self.mute_cancel = mute_cancel
        self.requests: dict[str, str] = {}  # goal UUID (hex) -> 'taken', 'sent' or 'failed'
        self.takes: list[tuple[str, float]] = []  # (goal UUID (hex), time.monotonic()) per take
        # goal UUID (hex) -> the feedback readers that this server's graph showed when it took the
        # goal request, as GID hex: whether a client's reader was discovered before its goal ran.
        self.readers_at_take: dict[str, list[str]] = {}
        self.counts = {'goal_requests': 0, 'goal_responses': 0, 'goal_response_errors': 0,
                       'cancel_requests': 0, 'cancel_requests_unanswered': 0}
        self._failed_send = threading.local()
        super().__init__(*args, **kwargs)
        self.feedback_topic = self._node.resolve_topic_name(args[2]) + '/_action/feedback'
        self._logger = _CountingLogger(self._logger, self._note_failed_send)
        # Every such warning, not only the first from its line (the default filter), is counted
        # and printed: each is a goal that its client will never hear of.
        warnings.filterwarnings('always', message=_RESPONSE_TIMED_OUT, category=RuntimeWarning)
        shown = warnings.showwarning

        def count_timed_out(message: Any, category: Any, *args: Any, **kwargs: Any) -> None:
            if str(message).startswith(_RESPONSE_TIMED_OUT):
                self._note_failed_send()
            shown(message, category, *args, **kwargs)

        warnings.showwarning = count_timed_out

    def take_data(self) -> dict:
        """Take as rclpy does, and note when a goal request left rmw's queue."""
        data = super().take_data()
        if 'goal' in data:
            key = bytes(data['goal'][1].goal_id.uuid).hex()
            with self.request_lock:
                self.takes.append((key, time.monotonic()))
        return data

    def _note_failed_send(self) -> None:
        self._failed_send.value = True

    async def _execute_cancel_request(self, request_header_and_message: Any) -> None:
        with self.request_lock:
            self.counts['cancel_requests'] += 1
        if not self.mute_cancel:
            await super()._execute_cancel_request(request_header_and_message)
            return
        with self.request_lock:  # taken from rcl, and never answered
            self.counts['cancel_requests_unanswered'] += 1

    async def _execute_goal_request(self, request_header_and_message: Any) -> None:
        key = bytes(request_header_and_message[1].goal_id.uuid).hex()
        readers = (feedback_reader_gids(self._node, self.feedback_topic)
                   if self.record_readers else None)
        with self.request_lock:
            if readers is not None:
                self.readers_at_take[key] = readers
            self.counts['goal_requests'] += 1
            self.requests[key] = 'taken'
        # The response is sent before the coroutine's first await that can suspend it (the goal
        # callback is synchronous here), so the flag is this request's.
        self._failed_send.value = False
        await super()._execute_goal_request(request_header_and_message)
        failed = getattr(self._failed_send, 'value', False)
        with self.request_lock:
            self.counts['goal_response_errors' if failed else 'goal_responses'] += 1
            self.requests[key] = 'failed' if failed else 'sent'


class TickingServer:
    """Action server that publishes ``order`` time-stamped feedback messages per goal."""

    def __init__(self, node: Node, executor: Executor, action: str, period: float,
                 pad: int = 0, depth: Optional[str] = None,
                 result_timeout: int = DEFAULT_RESULT_TIMEOUT_S,
                 late_feedback: float = 0.0, goal_depth: Optional[int] = None,
                 hold_goals: int = 0, record_readers: bool = False,
                 mute_cancel: bool = False, feedback_depth: Optional[int] = None,
                 result_pad: int = 0) -> None:
        """Create the action server on ``node`` and start the ticker thread."""
        self.executor = executor
        self.started = time.monotonic()
        # --hold-goals: goals of positive order wait after their first feedback until this many
        # were accepted; 0 holds nothing.
        self.hold_goals = hold_goals
        self.held_accepted = 0
        self.released_at: Optional[float] = None if hold_goals > 0 else self.started
        self.release_reason = ''
        self.peak_active = 0
        self.period = period
        self.late_feedback = late_feedback
        self.result_pad = result_pad
        self.late: list[tuple[float, Any, int]] = []  # (due, goal handle, k) after a success
        # A template copied per message: building a 2500-element list each time would cost the
        # server more CPU than the publish itself.
        self.template = array.array('i', [0] * (HEADER + pad))
        self.lock = threading.Lock()
        # id(goal handle) -> [goal handle, next k, order, done, first publish, last publish]
        self.active: dict[int, list[Any]] = {}
        self.published = 0
        self.published_per_goal: dict[str, int] = {}  # goal UUID (hex) -> messages published
        self.accepted = 0
        self.late_ticks = 0
        # Over finished goals: feedback intervals, and the seconds they took (the achieved rate).
        self.intervals = 0
        self.interval_s = 0.0
        self.running = True
        qos = queue_kwargs(depth)
        if goal_depth is not None:
            qos['goal_service_qos_profile'] = QoSProfile(
                depth=goal_depth, reliability=ReliabilityPolicy.RELIABLE)
        if feedback_depth is not None:
            qos['feedback_pub_qos_profile'] = QoSProfile(
                depth=feedback_depth, reliability=ReliabilityPolicy.RELIABLE)
        self.server = CountingActionServer(
            node, Fibonacci, action, execute_callback=self.execute, goal_callback=self.on_goal,
            cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=ReentrantCallbackGroup(), result_timeout=result_timeout,
            record_readers=record_readers, mute_cancel=mute_cancel, **qos)
        self.ticker = threading.Thread(target=self.tick, daemon=True)
        self.ticker.start()

    def on_goal(self, request: Fibonacci.Goal) -> GoalResponse:
        """Accept every goal of non-negative order."""
        return GoalResponse.REJECT if request.order < 0 else GoalResponse.ACCEPT

    def publish(self, goal_handle: Any, k: int) -> None:
        """Publish feedback ``k`` of a goal, stamped with the current wall-clock time."""
        sequence = array.array('i', self.template)
        now = time.time_ns()
        sequence[0], sequence[1], sequence[2] = k, now // 1_000_000_000, now % 1_000_000_000
        goal_handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
        key = bytes(goal_handle.goal_id.uuid).hex()
        with self.lock:
            self.published += 1
            self.published_per_goal[key] = max(self.published_per_goal.get(key, 0), k + 1)

    async def execute(self, goal_handle: Any) -> Fibonacci.Result:
        """Publish the first feedback at once; the ticker publishes the rest and ends the goal."""
        order = goal_handle.request.order
        first = time.monotonic()
        if order > 0:
            self.publish(goal_handle, 0)
        done = Future()
        entry = [goal_handle, 1 if order > 0 else 0, order, done, first, first]
        with self.lock:
            self.accepted += 1
            self.active[id(goal_handle)] = entry
            self.peak_active = max(self.peak_active, len(self.active))
            if order > 0:
                self.held_accepted += 1
                if self.held_accepted >= self.hold_goals:
                    self._release('all held goals accepted')
        outcome = await done
        if outcome == 'canceled':
            goal_handle.canceled()
        else:
            goal_handle.succeed()
        return Fibonacci.Result(sequence=array.array('i', [entry[1]] + [0] * self.result_pad))

    def hold(self) -> None:
        """Hold the goals that start from now on until :meth:`release` (the ``hold`` command)."""
        with self.lock:
            self.hold_goals = 2**62
            self.released_at = None
            self.release_reason = ''

    def release(self, reason: str) -> None:
        """Let the held goals go on (``--hold-goals``); the first call counts."""
        with self.lock:
            self._release(reason)

    def _release(self, reason: str) -> None:
        if self.released_at is None:
            self.released_at = time.monotonic()
            self.release_reason = reason

    def tick(self) -> None:
        """Every period, publish the next feedback of each running goal, or finish the goal."""
        due = time.monotonic()
        while self.running:
            due += self.period
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -self.period:
                # Behind by more than a period: count it and restart the schedule rather than
                # publishing a burst of catch-up ticks, which would distort the latency.
                self.late_ticks += 1
                due = time.monotonic()
            with self.lock:
                goals = list(self.active.items())
                holding = self.released_at is None
            finished = []
            for key, entry in goals:
                goal_handle, k, order, done = entry[:4]
                if holding and order > 0 and not goal_handle.is_cancel_requested:
                    continue
                if goal_handle.is_cancel_requested:
                    finished.append((key, done, 'canceled'))
                elif k >= order:
                    finished.append((key, done, 'succeeded'))
                    if self.late_feedback > 0 and order > 0:
                        self.late.append((time.monotonic() + self.late_feedback, goal_handle, k))
                else:
                    self.publish(goal_handle, k)
                    entry[1] = k + 1
                    entry[5] = time.monotonic()
            with self.lock:
                for key, _, _ in finished:
                    entry = self.active.pop(key)
                    self.intervals += max(0, entry[1] - 1)
                    self.interval_s += entry[5] - entry[4]
            for _, done, outcome in finished:
                done.set_result(outcome)
            self.publish_late()
            if finished:
                self.executor.wake()

    def publish_late(self) -> None:
        """Publish the feedback due after their goals' results (``--late-feedback``)."""
        now = time.monotonic()
        due = [item for item in self.late if item[0] <= now]
        self.late = [item for item in self.late if item[0] > now]
        for _, goal_handle, k in due:
            self.publish(goal_handle, k)

    def stats(self) -> dict[str, Any]:
        """Counters for the ``stats`` command."""
        usage = resource.getrusage(resource.RUSAGE_SELF)
        with self.server.request_lock:
            requests = dict(self.server.counts)
        with self.lock:
            return {**requests, 't': time.monotonic(), 'published': self.published,
                    'accepted': self.accepted, 'active': len(self.active),
                    'peak_active': self.peak_active, 'held_accepted': self.held_accepted,
                    'released': (None if self.released_at is None
                                 else self.released_at - self.started),
                    'release_reason': self.release_reason, 'maxrss_kb': usage.ru_maxrss,
                    'late_ticks': self.late_ticks, 'intervals': self.intervals,
                    'interval_s': self.interval_s, 'cpu_s': usage.ru_utime + usage.ru_stime,
                    'sys_s': usage.ru_stime,
                    'switches': usage.ru_nvcsw, 'preempted': usage.ru_nivcsw,
                    'guard': guard.status(), 'guard_calls': guard.call_counts(),
                    'guard_filter': guard.filter_counts(), 'guard_writers': guard.writer_limits(),
                    'guard_filter_class': guard.filter_class_counts(),
                    'guard_heartbeats': guard.heartbeat_counts(),
                    'guard_replies': guard.reply_counts(),
                    'guard_prefilter': guard.prefilter(),
                    'guard_feedback': guard.feedback_counts(),
                    'guard_status': guard.status_counts()}


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('action')
    parser.add_argument('period', type=float, help='feedback period, s')
    parser.add_argument('--pad', type=int, default=0, help='int32 elements after the header')
    parser.add_argument('--result-pad', type=int, default=0,
                        help="int32 elements after the count in each goal's result")
    parser.add_argument('--depth', help="every queue's depth, or 'all' (default: rclpy's)")
    parser.add_argument('--result-timeout', type=int, default=DEFAULT_RESULT_TIMEOUT_S,
                        help='seconds a finished goal stays on the server')
    parser.add_argument('--stats-every', type=float, default=0.0,
                        help='also print STATS every this many seconds')
    parser.add_argument('--late-feedback', type=float, default=0.0,
                        help='publish one more feedback (k = order) this many seconds after a '
                             "goal's success, as a sample resent after a loss arrives late")
    parser.add_argument('--executor', choices=['single', 'multi'], default='single',
                        help='SingleThreadedExecutor (default) or MultiThreadedExecutor')
    parser.add_argument('--goal-depth', type=int,
                        help="the goal service's depth alone (keep-last, reliable)")
    parser.add_argument('--feedback-depth', type=int,
                        help="the feedback writer's depth alone (keep-last, reliable)")
    parser.add_argument('--record-readers', action='store_true',
                        help='record the feedback readers in the graph when each goal is taken '
                             '(command readers)')
    parser.add_argument('--mute-cancel', action='store_true',
                        help='take cancel requests and never answer them (command stats counts '
                             'them)')
    parser.add_argument('--hold-goals', type=int, default=0,
                        help='goals wait after their first feedback until this many were accepted '
                             '(or the command release)')
    return parser.parse_args(argv)


def main(argv: list[str]) -> None:
    """Run the server until stdin closes."""
    args = parse_args(argv)
    rclpy.init()
    node = Node('cft_fib_server')
    executor = MultiThreadedExecutor() if args.executor == 'multi' else SingleThreadedExecutor()
    executor.add_node(node)
    server = TickingServer(node, executor, args.action, args.period, args.pad, args.depth,
                           args.result_timeout, args.late_feedback, args.goal_depth,
                           args.hold_goals, args.record_readers, args.mute_cancel,
                           args.feedback_depth, args.result_pad)
    # The RTPS GUIDs of the feedback and status writers, to tell their packets apart on the wire.
    writers = {name: [bytes(info.endpoint_gid).hex() for info in
                      node.get_publishers_info_by_topic(f'{args.action}/_action/{name}')]
               for name in ('feedback', 'status')}
    # And of the reply writers (rmw_fastrtps's topics rr/<service>Reply, outside ROS's names).
    resolved = node.resolve_topic_name(args.action)
    writers.update({name: [bytes(info.endpoint_gid[:16]).hex() for info in
                           node.get_publishers_info_by_topic(f'rr{resolved}/_action/{name}Reply',
                                                             no_mangle=True)]
                    for name in ('send_goal', 'cancel_goal', 'get_result')})
    out = threading.Lock()

    def report() -> None:
        line = 'STATS ' + json.dumps({**server.stats(), 'writers': writers})
        with out:
            print(line, flush=True)

    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    stop = threading.Event()
    if args.stats_every > 0:
        def report_every() -> None:
            while not stop.wait(args.stats_every):
                report()
        threading.Thread(target=report_every, daemon=True).start()
    print('STATUS', guard.is_active(), guard.status(), flush=True)
    print('READY', flush=True)
    for line in sys.stdin:
        if line.strip() == 'stats':
            report()
        elif line.strip() == 'release':
            server.release('command')
        elif line.strip() == 'hold':
            server.hold()
        elif line.strip() == 'goals':
            with server.lock:
                counts = json.dumps(server.published_per_goal)
            with out:
                print('GOALS ' + counts, flush=True)
        elif line.strip() == 'requests':
            with server.server.request_lock:
                states = json.dumps(server.server.requests)
            with out:
                print('REQUESTS ' + states, flush=True)
        elif line.strip() == 'readers':
            with server.server.request_lock:
                readers = json.dumps(server.server.readers_at_take)
            with out:
                print('READERS ' + readers, flush=True)
        elif line.strip() == 'readers now':
            topic = server.server.feedback_topic
            with out:
                print('READERS_NOW ' + json.dumps(feedback_reader_gids(node, topic)), flush=True)
        elif line.strip() == 'takes':
            with server.server.request_lock:
                takes = json.dumps(server.server.takes)
            with out:
                print('TAKES ' + takes, flush=True)
    # A crash watcher would count an abort at exit as a crash of the server; without the clean
    # destruction, the participant's shared-memory segment and ports stay in /dev/shm (measured:
    # 6 files a server, thousands over a few sessions).
    stop.set()
    server.running = False

    def destroy() -> None:
        server.server.destroy()
        node.destroy_node()
    leave_spinning_process(executor, [server.ticker, spinner], destroy)


if __name__ == '__main__':
    main(sys.argv[1:])
