# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The action client's finished goals, kept for their late feedback, and released after a grace.

Feedback, status and result travel on different topics, so a goal's last feedback can arrive after
its result. rclpy forgets a goal's feedback callback when the result arrives, and so loses that
feedback; the action client keeps the callback for a grace period instead, and decides by the
server's own clock: feedback stamped after the goal's result response is dropped, as rclpy's
contract says.
"""

from __future__ import annotations

import time
from typing import Any, Callable

from rclpy.callback_groups import CallbackGroup
from rclpy.node import Node

from cft_action.action._paused_timer import PausedTimer

__all__ = ['FinishedGoals']


class FinishedGoals:
    """Finished goals, the source timestamps of their results, and the timer that releases them.

    Only goals with a feedback callback count. A goal is released ``grace`` seconds after it
    finished, once the feedback queue has been seen empty since: its callback is dropped, and
    ``release_terms`` drops its filter term. The timer checks every ``period`` seconds, tells
    ``release_terms`` whether the client has been idle (no goal sent or finished) for a period,
    and keeps running while goals remain or ``release_terms`` returns True.

    Every method takes ``lock``; :meth:`drained` needs none (one store, from the executor's wait).

    :param node: The client's node, for the timer.
    :param callback_group: The client's callback group, for the timer.
    :param lock: The client's lock (re-entrant).
    :param callbacks: rclpy's goal UUID -> feedback callback.
    :param release_terms: ``release_terms(goal_uuids, idle) -> bool``: drop these goals' filter
        terms; return whether terms of finished goals remain, to drop later.
    :param grace: Seconds a finished goal is kept.
    :param period: Seconds between checks, and of idleness.
    """

    def __init__(self, node: Node, callback_group: CallbackGroup, lock: Any,
                 callbacks: dict[bytes, Callable],
                 release_terms: Callable[[list[bytes], bool], bool], *, grace: float,
                 period: float) -> None:
        self._lock, self._callbacks, self._release_terms = lock, callbacks, release_terms
        self._grace, self._period = grace, period
        self._finished: dict[bytes, float] = {}  # goal UUID -> when it finished
        # goal UUID -> source timestamp of its result response (server clock, ns; 0: unknown)
        self._result_stamps: dict[bytes, int] = {}
        self._last_activity = time.monotonic()
        self._drained_at = time.monotonic()  # last wait that found no feedback queued
        self._timer = PausedTimer(node, period, self._check, callback_group)

    def sent(self, goal_uuid: bytes) -> None:
        """A goal with a feedback callback is being sent; what its UUID left is not its own."""
        with self._lock:
            self._last_activity = time.monotonic()
            self._finished.pop(goal_uuid, None)
            self._result_stamps.pop(goal_uuid, None)

    def drained(self) -> None:
        """A wait found no feedback queued."""
        self._drained_at = time.monotonic()

    def result(self, goal_uuid: bytes, stamp: int) -> None:
        """The goal's result response came, published at ``stamp`` (0: unknown)."""
        with self._lock:
            if goal_uuid in self._callbacks:
                # The first result answers the goal; a later request is answered later still.
                self._result_stamps.setdefault(goal_uuid, stamp)

    def dropped(self, goal_uuid: bytes, stamp: int) -> bool:
        """Whether feedback published at ``stamp`` goes to no callback: none, or after the result.

        Both timestamps come from the server's clock: it wrote the result response only after its
        execute callback had returned, so feedback published in there is stamped earlier.
        """
        with self._lock:
            if goal_uuid not in self._callbacks:
                return True
            result_stamp = self._result_stamps.get(goal_uuid)
        if result_stamp is None:
            return False
        if not (result_stamp and stamp):
            return True  # no ordering evidence: as rclpy, which forgets the callback at the result
        return stamp > result_stamp

    def finished(self, goal_uuids: list[bytes]) -> None:
        """These goals finished (those not noted already); release them after the grace."""
        now = time.monotonic()
        with self._lock:
            new = [u for u in goal_uuids if u in self._callbacks and u not in self._finished]
            for goal_uuid in new:
                self._finished[goal_uuid] = now
            if new:
                self._last_activity = now
                self._timer.resume()

    def destroy(self) -> None:
        """Stop the timer."""
        self._timer.destroy()

    def _check(self) -> None:
        now = time.monotonic()
        with self._lock:
            due = [goal_uuid for goal_uuid, finished_at in self._finished.items()
                   if now - finished_at >= self._grace and finished_at < self._drained_at]
            for goal_uuid in due:
                del self._finished[goal_uuid]
                self._result_stamps.pop(goal_uuid, None)
                self._callbacks.pop(goal_uuid, None)
            idle = not self._finished and now - self._last_activity >= self._period
            if not self._release_terms(due, idle) and not self._finished:
                self._timer.pause()
