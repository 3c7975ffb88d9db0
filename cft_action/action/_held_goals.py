# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Goal requests held until the filter version that matches their goal has reached the server.

A filter update travels by discovery and a goal request by the goal service, so the request can
overtake the update at the server, whose feedback writer then drops the goal's first feedback with
its old filter (docs/INTERNALS.md, "Proof of arrival"). The action client therefore holds such a
request until its :class:`cft_action.topics.arrival.ArrivalGate` has proven the version, polling the
gate from a timer of the client's callback group, and sends the held requests in call order.

A proof that does not come within the timeout is not waited for again: from then on goals go out
at once, as rclpy sends them, while one proof goes on in the background, and holding resumes only
once that proof has come. A server that never answers the probe (a cancel service that takes
requests and never replies, or replies that rmw keeps dropping) so costs a client life one hold,
not one per goal.
"""

from __future__ import annotations

import time
from typing import Any, Callable, NamedTuple, Optional

from action_msgs.srv import CancelGoal
from rclpy.callback_groups import CallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.task import Future
from unique_identifier_msgs.msg import UUID

from cft_action.action._paused_timer import PausedTimer
from cft_action._rclpy_compat import PromptLogger
from cft_action.topics.arrival import ArrivalGate, ProbeTarget, RemotePublishers
from cft_action.action.goal_filter import random_uuid4

__all__ = ['HeldGoal', 'HeldGoals', 'cancel_goal_probe']


def cancel_goal_probe(service_name: str, qos_profile: QoSProfile) -> dict[bytes, list[ProbeTarget]]:
    """The proof for an action client: a reply of the action's ``cancel_goal`` service.

    A random goal id with a zero stamp asks to cancel that goal only, which no server has: the
    reply is ``ERROR_UNKNOWN_GOAL_ID``, and no cancel callback runs. The service is the action's
    own, so its one target is keyed by no participant.
    """
    request = CancelGoal.Request()
    request.goal_info.goal_id.uuid = list(random_uuid4())
    return {b'': [ProbeTarget(CancelGoal, service_name, request, qos_profile)]}


class HeldGoal(NamedTuple):
    """A goal request held until the filter version it needs has reached the server."""

    version: int  # the filter version it needs; -1: none, it only keeps its place in the order
    goal: Any
    feedback_callback: Optional[Callable]
    goal_uuid: UUID
    future: Future


def _forward(source: Future, target: Future) -> None:
    """Complete ``target`` as ``source`` completes, and cancel ``source`` with ``target``."""
    def done(_: Future) -> None:
        if target.done():
            return
        if source.cancelled():
            target.cancel()
        elif source.exception() is not None:
            target.set_exception(source.exception())
        else:
            target.set_result(source.result())

    target.add_done_callback(lambda _: source.cancel() if target.cancelled() else None)
    source.add_done_callback(done)


class HeldGoals:
    """The action client's held goal requests, and the timer that polls its arrival gate.

    Every call but the timer's and :meth:`await_proof` is made with ``lock`` held, which those
    take themselves.

    :param node: The client's node, for the timer.
    :param callback_group: The client's callback group, for the timer.
    :param gate: The client's arrival gate.
    :param lock: The client's lock.
    :param send: rclpy's ``send_goal_async``, for the requests once released.
    :param version_now: The version that a proof begun now proves: the reader's update count.
    :param logger: For the one warning when a proof times out.
    :param probed_service: The service whose reply is the proof, for that warning.
    :param timeout: Seconds that a proof may take, from its first poll.
    :param poll_period: Seconds between polls while requests are held.
    :param background_poll_period: Seconds between polls of the background proof, once holding
        is suspended.
    """

    def __init__(self, node: Node, callback_group: CallbackGroup, gate: ArrivalGate, lock: Any,
                 send: Callable[[Any, Optional[Callable], UUID], Future],
                 version_now: Callable[[], int], logger: PromptLogger, probed_service: str, *,
                 timeout: float, poll_period: float, background_poll_period: float) -> None:
        self._gate, self._lock, self._send, self._version_now = gate, lock, send, version_now
        self._logger, self._probed_service, self._timeout = logger, probed_service, timeout
        self._poll_period, self._background_poll_period = poll_period, background_poll_period
        self._queue: list[HeldGoal] = []
        self._destroyed = False
        self.count = 0  # requests held since construction
        #: Whether a proof timed out and none has come since: goals are then not held.
        self.suspended = False
        self._timer = PausedTimer(node, poll_period, self._poll, callback_group)

    @property
    def waiting(self) -> tuple[HeldGoal, ...]:
        """The goals held now, oldest first."""
        return tuple(self._queue)

    def needed(self) -> int:
        """The latest version that a held request waits for; -1 when none waits."""
        return max((held.version for held in self._queue), default=-1)

    def must_hold(self, version: int, writer_is_remote: Callable[[], bool]) -> bool:
        """Whether a request that needs ``version`` waits: behind others, or for a proof.

        While holding is suspended it never waits for a proof, and a proof goes on in the
        background instead, so that holding resumes once the server answers.
        """
        if self._queue:
            return True
        if self._gate.is_confirmed(version) or not writer_is_remote():
            return False
        if self.suspended:
            self._begin()
            return False
        return True

    def hold(self, held: HeldGoal) -> Future:
        """Hold a request until its version is proven, and behind the requests held before it."""
        self._queue.append(held)
        self.count += 1
        self._begin()  # or poll the proof that runs already (the client's first, of its reader)
        return held.future

    def destroy(self) -> None:
        """Stop polling; the held requests are never sent."""
        with self._lock:
            self._destroyed = True  # a poll that runs now begins no new proof
            self._gate.end()
        self._timer.destroy()

    def await_proof(self, deadline: float) -> bool:
        """Poll the proof begun at construction (or a new one) until it came or ``deadline``.

        Takes ``lock`` for each poll; call it without.
        """
        while True:
            with self._lock:
                if self._gate.is_confirmed(0):
                    return True
                self._gate.begin(self._version_now())  # unless one runs
                came = self.poll_proof()
            if came is not None or time.monotonic() >= deadline:
                return bool(came)
            time.sleep(self._poll_period)

    def proof_state(self, filtered: bool) -> dict[str, Any]:
        """The proof's fields of ``FeedbackFilterState``; ``filtered``: whether a filter
        plan is in force (without one, nothing needs a proof)."""
        return {'confirmed': not filtered or self._gate.is_confirmed(self.needed()),
                'held_goals': self.count, 'arrival_timeouts': self._gate.timeouts,
                'holds_suspended': self.suspended}

    def await_server_proof(self, writers: RemotePublishers, timeout_sec: Optional[float],
                           started: float) -> None:
        """``wait_for_server``'s wait for the proof that the server has the feedback reader.

        The server's services can show in the graph before its feedback writer: that is waited
        for first. Then, unless the writer is in this process, the proof is waited for at most
        ``timeout`` seconds (where it does not come, that is the proof's timeout, as a held
        goal's). Both within ``timeout_sec`` from ``started`` (a monotonic time); not at all if
        the proof came before or holding is suspended. Call it without ``lock``.
        """
        with self._lock:
            if self._gate.is_confirmed(0) or self.suspended:
                return

        def left() -> float:
            if timeout_sec is None or timeout_sec < 0:
                return self._timeout
            return min(self._timeout, max(0.0, timeout_sec - (time.monotonic() - started)))

        seen_by = time.monotonic() + left()
        while not writers.seen() and time.monotonic() < seen_by:
            time.sleep(self._poll_period)
        if not writers.any():
            return
        budget = left()
        if budget >= self._timeout:  # one poll after the proof's own timeout (from its 1st poll)
            budget += self._poll_period
        if not self.await_proof(time.monotonic() + budget):
            self._logger.debug('wait_for_server: the server did not prove that it has the '
                               'feedback reader in time; the first goal will be held')

    def poll_proof(self) -> Optional[bool]:
        """Poll the running proof: True once it came, False once it timed out, else None.

        A timeout suspends holding (logged the first time) and begins the background proof; a
        proof that came ends the suspension. Call it with ``lock`` held.
        """
        came = self._gate.poll(time.monotonic(), None if self.suspended else self._timeout)
        if came:
            if self.suspended:
                self._logger.info(f'the action server answered {self._probed_service}: goals '
                                  'are held again until their filter is proven at the server')
            self.suspended = False
            self._timer.set_period(self._poll_period)
        elif came is False:
            if self._gate.timeouts == 1:
                self._logger.warning(
                    f'the action server did not answer {self._probed_service} within '
                    f'{self._timeout:g} s, so that its feedback writer has this client\'s '
                    'feedback filter is not proven: goals are sent without that proof from now '
                    'on, as rclpy sends them, until the server answers, and the first feedback '
                    'that the server publishes for a goal may be lost meanwhile')
            self.suspended = True
            self._timer.set_period(self._background_poll_period)
            self._begin()
        return came

    def _begin(self) -> None:
        self._gate.begin(self._version_now())  # unless one runs
        self._timer.resume()

    def _poll(self) -> None:
        with self._lock:
            if self._destroyed:
                return
            if not self._gate.proving:
                self._timer.pause()
                return
            came = self.poll_proof()
            if came is None:
                return
            self._release(self._gate.confirmed if came else self.needed())
            if self._queue:
                self._begin()
            elif not self._gate.proving:
                self._timer.pause()

    def _release(self, up_to_version: int) -> None:
        """Send the held requests, in order, up to the first one that needs a later version."""
        while self._queue and self._queue[0].version <= up_to_version:
            held = self._queue.pop(0)
            if held.future.cancelled():
                continue
            _forward(self._send(held.goal, held.feedback_callback, held.goal_uuid), held.future)
