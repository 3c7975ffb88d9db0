# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The action client's feedback filter: its goal plan and its filtered reader, kept in step.

:class:`cft_action.action.goal_filter.GoalFilterPlan` decides which expression the goals need, and
:class:`cft_action.topics._filtered_reader.FilteredReader` is the one way to set it; this object
applies each of the plan's expressions as one update of the reader, so the plan's revision is the
reader's update count, the version that :class:`cft_action.topics.arrival.ArrivalGate` proves. Where
a change fails, the filter is abandoned for good and the client behaves as plain rclpy.
"""

from __future__ import annotations

from typing import Any, Callable, ContextManager, Iterable, NamedTuple, Optional

from cft_action import _rcl
from cft_action.topics._filtered_reader import FilteredReader
from cft_action._rclpy_compat import PromptLogger
from cft_action.topics.filters import ContentFilterOptions, MATCH_ALL
from cft_action.action.goal_filter import ExpressionTooLong, GoalFilterPlan, random_uuid4

__all__ = ['FeedbackFilter', 'FeedbackFilterState']


class FeedbackFilterState(NamedTuple):
    """A snapshot of an :class:`ActionClient`'s feedback filter.

    :ivar mode: ``'client'``, ``'goals'`` or ``'off'``.
    :ivar active: whether the middleware filters the feedback subscription.
    :ivar reason: why the filter is not active; empty when it is.
    :ivar expression: the filter expression in force; empty when not active.
    :ivar updates: filter changes sent after the first installation; each is an event at the
        server's writer.
    :ivar live_goals: goals that hold an exact term in the expression.
    :ivar feedback_taken: feedback messages taken from rcl by this client.
    :ivar feedback_dropped: of those, messages not given to a callback: there was none for their
        goal, or the server published them after the goal's result.
    :ivar confirmed: whether the server's feedback writer is known to apply every term that a goal
        sent so far needs. A goal whose term came with an update is held until it is.
    :ivar held_goals: goal requests that were held for that proof, since construction.
    :ivar arrival_timeouts: times the proof did not come within ``FILTER_ARRIVAL_TIMEOUT`` and the
        held goals were sent without it.
    :ivar holds_suspended: whether, since such a timeout, goals are sent at once, without a
        proof, as rclpy sends them: a client waits for a proof that does not come only once, and
        holds goals again once a proof, which goes on in the background, has come.
    :ivar filtered_in: where other goals' feedback is dropped: ``'writer'`` (the server's writer
        does not send it: a guarded server, or ``writer_filtering='any'``), ``'reader'`` (it
        crosses the network and this client's DDS reader drops it before Python: an unguarded
        server), ``'none'`` (not filtered: rclpy drops it in Python), or ``'unknown'`` (no
        feedback has arrived yet, or this process discovered the server before its first use of
        cft_action, which then cannot read the server's discovery data, where a guarded server
        says that it filters). On Fast DDS 3.3+ the reader has no filter (``active`` is False) but
        asks a guarded server for its own goals' feedback only: ``'writer'`` when every feedback
        writer it matches says it filters, ``'none'`` when one does not (an unguarded server:
        plain rclpy), ``'unknown'`` before it matches one.
    """

    mode: str
    active: bool
    reason: str
    expression: str
    updates: int
    live_goals: int
    feedback_taken: int
    feedback_dropped: int
    confirmed: bool = True
    held_goals: int = 0
    arrival_timeouts: int = 0
    filtered_in: str = 'unknown'
    holds_suspended: bool = False


class FeedbackFilter:
    """The plan of an action client's feedback filter, and the reader that applies it.

    :param logger: The client's logger.
    :param mode: ``'client'``, ``'goals'`` or ``'off'``.
    :param filter_class: The library's filter class to filter with (``writer_filtering='guarded'``),
        or None for DDS-SQL.
    """

    def __init__(self, logger: PromptLogger, mode: str, *, filter_class: Optional[str]) -> None:
        self.mode = mode
        self.reader = FilteredReader(
            logger, match_all=MATCH_ALL, filter_class=filter_class,
            unfiltered='feedback filter not used, all feedback is received as with rclpy')
        self.plan: Optional[GoalFilterPlan] = None  # None: the filter is not (or no longer) used
        self.installed = False  # whether install() ran
        self._logger = logger
        self._logged_explicit_uuid = False
        self._logged_unguarded = False
        # On Fast DDS 3.3+: the rclpy handle and rcl_subscription_t * of the feedback reader that
        # asks a guarded server for its own goals' feedback only (_rcl.mark_own_goals_reader).
        self._own_feedback: Optional[tuple[ContextManager[Any], int]] = None

    def install(self, handle: ContextManager[Any], pointer: Optional[int], topic: str,
                pointer_reason: str, cft_supported: bool) -> None:
        """Set the first filter, before any executor can see the feedback subscription.

        :param pointer: The feedback subscription's ``rcl_subscription_t *``; None if not found.
        :param pointer_reason: Why it was not found.
        :param cft_supported: Whether the rmw implementation has content filters.
        """
        self.installed = True
        if self.mode == 'off':
            self.reader.fall_back('feedback_filter is off', log=False)
        elif not cft_supported:
            self.reader.fall_back('the rmw implementation has no content filter')
        elif pointer is None:
            self.reader.fall_back(pointer_reason)
        elif self.reader.filter_class and (why := _rcl.filter_class_status()):
            self._ask_own_feedback(handle, pointer, why)
        else:
            plan = GoalFilterPlan(self.mode)
            if self.reader.install(handle, pointer, topic,
                                   ContentFilterOptions(plan.initial(), [])):
                self.plan = plan

    def _ask_own_feedback(self, handle: ContextManager[Any], pointer: int, why: str) -> None:
        """Where the library's filter class cannot be used (Fast DDS 3): on Fast DDS 3.3+, mark the
        reader so that a guarded server sends it only its own goals' feedback; else plain rclpy."""
        with handle:
            refused = _rcl.mark_own_goals_reader(pointer)
        unfiltered = f'the {self.reader.filter_class} filter class cannot be used here ({why})'
        if refused:
            self.reader.fall_back(f'{unfiltered}, and {refused}')
            return
        self._own_feedback = (handle, pointer)
        self.reader.fall_back(
            f"{unfiltered}: the feedback reader asks a guarded server (Fast DDS 3.3+) for its own "
            "goals' feedback only; an unguarded server sends all of it, as to plain rclpy",
            log=False)

    def uuid_for(self, feedback: bool) -> Optional[bytes]:
        """A fresh UUID: one the filter matches for a goal with feedback, else one it does not.

        None when there is no filter (rclpy then generates one).
        """
        if self.plan is None:
            return None
        return self.plan.uuid_for_feedback() if feedback else self.plan.untagged_uuid()

    def new_goal_uuid(self) -> bytes:
        """A fresh UUID that the filter already matches; a random one without a filter."""
        return self.plan.uuid_for_feedback() if self.plan else random_uuid4()

    def watch(self, goal_uuid: bytes) -> int:
        """Match this goal's feedback, growing the filter if it must.

        :return: The version of the filter that first matched the goal: 0 when the installed filter
            does; -1 when there is no filter, so nothing to wait for.
        """
        if self.plan is None:
            return -1
        if self.plan.watch(goal_uuid):
            if self.plan.mode == 'client' and not self._logged_explicit_uuid:
                self._logged_explicit_uuid = True
                self._logger.info(
                    "a goal_uuid without this client's tag is added to the feedback filter, which "
                    'costs a filter update at the server; ActionClient.new_goal_uuid() avoids it')
            self._update(self.plan.grow)
        matched = self.plan.revision_matching(goal_uuid) if self.plan is not None else None
        return -1 if matched is None else matched

    def release(self, goal_uuids: list[bytes], idle: bool) -> bool:
        """Drop the terms of released goals; shrink once ``idle``.

        :return: Whether the filter still has terms of finished goals, to drop later.
        """
        if self.plan is None:
            return False
        for goal_uuid in goal_uuids:
            self.plan.finish(goal_uuid)
        # One shrink once the client is idle, not one per release: each update is an event at the
        # server's writer.
        if idle:
            self._update(self.plan.shrink)
        return self.plan is not None and self.plan.has_stale_terms()

    def abandon(self, reason: str) -> None:
        """Let all feedback through, for good."""
        self.plan = None
        self.reader.abandon(reason)

    def _update(self, make_expression: Callable[[], Optional[str]]) -> None:
        """Change the filter in place; on failure, fall back to receiving all feedback."""
        try:
            expression = make_expression()
        except ExpressionTooLong as e:
            self.abandon(f'a filter update failed: {e}')
            return
        if expression is not None:
            self.reader.update(ContentFilterOptions(expression, []))
            if self.reader.filter is None:
                self.plan = None

    def state(self, feedback_taken: int, feedback_dropped: int,
              writers: Callable[[], Iterable[Any]], **proof: Any) -> FeedbackFilterState:
        """A snapshot of the filter, with the client's counters and its proof state (``confirmed``,
        ``held_goals``, ``arrival_timeouts``, ``holds_suspended``)."""
        common = self.reader.state
        return FeedbackFilterState(
            self.mode, common.active, common.reason, common.expression, common.updates,
            live_goals=self.plan.live_goals if self.plan else 0, feedback_taken=feedback_taken,
            feedback_dropped=feedback_dropped,
            filtered_in=self.filtered_in(feedback_taken, writers), **proof)

    def filtered_in(self, feedback_taken: int, writers: Callable[[], Iterable[Any]]) -> str:
        """Where other goals' feedback is dropped; see :class:`cft_action.FeedbackFilterState`.

        :param writers: The GIDs of the server's feedback writers.
        """
        if self._own_feedback is None:
            return self.reader.filtered_in(feedback_taken, writers)
        handle, pointer = self._own_feedback
        with self.reader.lock:
            if self.reader.ended:
                return 'unknown'
            with handle:
                marked, matched = _rcl.marked_writers(pointer)
        if matched <= 0:
            return 'unknown'
        return 'writer' if marked == matched else 'none'

    def log_if_unguarded(self, feedback_taken: int, writers: Callable[[], Iterable[Any]]) -> None:
        """Say once that the server does not filter for this client, once there is evidence.

        Asked at every 10th sample taken, up to the 100th, until the answer is known: it reads the
        ROS graph.
        """
        if self._logged_unguarded or feedback_taken > 100 or feedback_taken % 10:
            return
        where = self.filtered_in(feedback_taken, writers)
        if where == 'unknown':
            return
        self._logged_unguarded = True  # asked and answered: once is enough
        if where == 'none' and self._own_feedback is not None:
            self._logger.info(
                "the action server's writer does not filter this client's feedback (on Fast DDS "
                "3.3+ it does under 'cft-action guard', unless CFT_GUARD_FEEDBACK=off there): "
                "other goals' feedback reaches this client, which drops it in Python as plain "
                'rclpy does (docs/COMPATIBILITY.md, "Fast DDS 3")')
        if where != 'reader':
            return
        self._logger.info(
            "the action server's writer does not filter this client's feedback (the server does "
            "not run under 'cft-action guard'): other goals' feedback crosses the network to this "
            "client and its DDS reader drops it before Python. Under the guard the server would "
            'not send it (README, "What it saves")')
