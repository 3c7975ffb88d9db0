# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Goal requests held until the filter version that matches their goal has reached the server.

A filter update travels by discovery and a goal request by the goal service, so the request can
overtake the update at the server, whose feedback writer then drops the goal's first feedback with
its old filter (docs/INTERNALS.md, "Proof of arrival"). The action client therefore holds such a
request until its :class:`cft_action.arrival.ArrivalGate` has proven the version, polling the
gate from a timer of the client's callback group, and sends the held requests in call order.
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

from cft_action._paused_timer import PausedTimer
from cft_action._rclpy_compat import PromptLogger
from cft_action.arrival import ArrivalGate, ProbeTarget
from cft_action.goal_filter import random_uuid4

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

    Every call but the timer's is made with ``lock`` held, which the timer takes too.

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
    """

    def __init__(self, node: Node, callback_group: CallbackGroup, gate: ArrivalGate, lock: Any,
                 send: Callable[[Any, Optional[Callable], UUID], Future],
                 version_now: Callable[[], int], logger: PromptLogger, probed_service: str, *,
                 timeout: float, poll_period: float) -> None:
        self._gate, self._lock, self._send, self._version_now = gate, lock, send, version_now
        self._logger, self._probed_service, self._timeout = logger, probed_service, timeout
        self._queue: list[HeldGoal] = []
        self.count = 0  # requests held since construction
        self._timer = PausedTimer(node, poll_period, self._poll, callback_group)

    @property
    def waiting(self) -> tuple[HeldGoal, ...]:
        """The goals held now, oldest first."""
        return tuple(self._queue)

    def needed(self) -> int:
        """The latest version that a held request waits for; -1 when none waits."""
        return max((held.version for held in self._queue), default=-1)

    def must_hold(self, version: int, writer_is_remote: Callable[[], bool]) -> bool:
        """Whether a request that needs ``version`` waits: behind others, or for a proof."""
        return bool(self._queue) or (not self._gate.is_confirmed(version) and writer_is_remote())

    def hold(self, held: HeldGoal) -> Future:
        """Hold a request until its version is proven, and behind the requests held before it."""
        self._queue.append(held)
        self.count += 1
        self._begin()  # or poll the proof that runs already (the client's first, of its reader)
        return held.future

    def destroy(self) -> None:
        """Stop polling; the held requests are never sent."""
        self._timer.destroy()
        with self._lock:
            self._gate.end()

    def _begin(self) -> None:
        self._gate.begin(self._version_now())  # unless one runs
        self._timer.resume()

    def _poll(self) -> None:
        with self._lock:
            if not self._gate.proving:
                self._timer.pause()
                return
            came = self._gate.poll(time.monotonic(), self._timeout)
            if came is None:
                return
            if came:
                self._release(self._gate.confirmed)
            else:
                if self._gate.timeouts == 1:
                    self._logger.warning(
                        f'the action server did not answer {self._probed_service} within '
                        f'{self._timeout:g} s, so that its feedback writer has this client\'s '
                        'feedback filter is not proven: held goals are sent without it, and the '
                        'first feedback that the server publishes for them may be lost')
                self._release(self.needed())
            if self._queue:
                self._begin()
            else:
                self._timer.pause()

    def _release(self, up_to_version: int) -> None:
        """Send the held requests, in order, up to the first one that needs a later version."""
        while self._queue and self._queue[0].version <= up_to_version:
            held = self._queue.pop(0)
            if held.future.cancelled():
                continue
            _forward(self._send(held.goal, held.feedback_callback, held.goal_uuid), held.future)
