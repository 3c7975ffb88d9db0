# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""A drop-in :class:`rclpy.action.ActionClient` whose feedback subscription is content-filtered.

An action server publishes the feedback of all goals on one topic, so a plain client receives,
deserializes and drops the feedback of every other client's goals. This client filters its
feedback subscription on ``goal_id.uuid``, with the library's own filter class: a server run under
``cft-action guard`` then sends it only its own goals' feedback, and any other server sends it
everything, as to a plain client, while the client's DDS reader drops other goals' feedback before
Python (docs/INTERNALS.md section 16). rclpy's own UUID check still guards every callback, in every
mode.

Feedback, status and result travel on different topics, so a goal's last feedback can arrive after
its result. rclpy forgets a goal's feedback callback when the result arrives, and so loses that
feedback; this client keeps the callback for a grace period, and decides by the server's own
clock: the source timestamps of the feedback sample and of the result response. Feedback that the
server published before the result is delivered, and feedback published after it is not, which is
rclpy's contract.
"""

from __future__ import annotations

import os
import time
from typing import Any, Callable, NamedTuple, Optional

from action_msgs.msg import GoalStatus
from action_msgs.srv import CancelGoal
from rclpy.node import Node
from rclpy.qos import qos_profile_services_default
from rclpy.task import Future
from unique_identifier_msgs.msg import UUID

from cft_action import _rcl
from cft_action._filtered_reader import FilteredReader
from cft_action._rclpy_compat import CompatActionClient, PromptLogger
from cft_action.arrival import node_participant, participant_of, ServiceProbe
from cft_action.errors import InvalidArgumentError
from cft_action.filters import ContentFilterOptions, MATCH_ALL
from cft_action.goal_filter import ExpressionTooLong, GoalFilterPlan, MODES, random_uuid4
from cft_action.subscription import is_content_filter_supported

__all__ = ['ActionClient', 'FeedbackFilterState', 'FEEDBACK_FILTER_ENV', 'WRITER_FILTERING_ENV',
           'WRITER_FILTERING']

#: Environment variable with which operators override the ``feedback_filter`` argument.
FEEDBACK_FILTER_ENV = 'CFT_ACTION_FEEDBACK_FILTER'

#: Environment variable with which operators override the ``writer_filtering`` argument.
WRITER_FILTERING_ENV = 'CFT_ACTION_WRITER_FILTERING'

#: Which servers' writers may filter: ``'guarded'`` (the default), only those run under
#: ``cft-action guard``, which know the library's filter class; ``'any'``, every Fast DDS writer,
#: with a DDS-SQL filter, which costs an unguarded server time and can crash it (docs/SAFETY.md).
WRITER_FILTERING = ('guarded', 'any')

_TERMINAL = frozenset({GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED,
                       GoalStatus.STATUS_ABORTED})

#: Seconds a finished goal keeps its callback and filter term, for feedback that the server
#: published before the result. Feedback, status and result travel on different topics, so the
#: last feedback may arrive after them, and much later when a sample was lost on the way: a
#: reliable reader then holds back everything after the gap until the writer's next heartbeat
#: (every 3 s in Fast DDS) gets it resent. Measured on a loaded 2-core machine: a 200-goal burst
#: had feedback delivered 2.8 s after its goals' terminal status, which a 1 s grace dropped (352
#: of 600 messages). Ten seconds cover three heartbeat rounds. The callback is also kept until the
#: feedback queue has been seen empty since the goal finished.
FINISHED_GOAL_GRACE = 10.0

#: Seconds between checks for finished goals to release, and of idleness (no goal sent or
#: finished) after which ``goals`` mode drops the terms of released goals from its filter.
RELEASE_CHECK_PERIOD = 1.0

#: Seconds a goal request is held for the proof that the server's feedback writer has the filter
#: update that matches the goal, counted from the executor's first poll of the probe. The proof is
#: a reply of the server's cancel service, so a server that answers nothing for this long would not
#: answer the goal either; the goal is then sent anyway, as rclpy sends it, and its first feedback
#: may be lost.
FILTER_ARRIVAL_TIMEOUT = 5.0

#: Seconds between polls of the arrival probe while goal requests are held.
ARRIVAL_POLL_PERIOD = 0.01


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
    :ivar filtered_in: where other goals' feedback is dropped: ``'writer'`` (the server's writer
        does not send it: a guarded server, or ``writer_filtering='any'``), ``'reader'`` (it
        crosses the network and this client's DDS reader drops it before Python: an unguarded
        server), ``'none'`` (not filtered: rclpy drops it in Python), or ``'unknown'`` (no
        feedback has arrived yet to tell).
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


class _HeldGoal(NamedTuple):
    """A goal request held until the filter term it needs has reached the server."""

    revision: int  # the filter revision it needs; 0: none, it only keeps its place in the order
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


def _resolve_writer_filtering(writer_filtering: str) -> str:
    value = os.environ.get(WRITER_FILTERING_ENV) or writer_filtering
    if value not in WRITER_FILTERING:
        source = (f'environment variable {WRITER_FILTERING_ENV}'
                  if os.environ.get(WRITER_FILTERING_ENV) else 'writer_filtering')
        raise InvalidArgumentError(
            f'{source}={value!r}: expected one of {", ".join(WRITER_FILTERING)}')
    return value


def _resolve_mode(feedback_filter: Optional[str], optimization: Optional[bool]) -> str:
    from_env = os.environ.get(FEEDBACK_FILTER_ENV)
    if optimization is not None:
        implied = 'client' if optimization else 'off'
        if feedback_filter is not None and (feedback_filter == 'off') == optimization:
            raise InvalidArgumentError(
                f'enable_feedback_msg_optimization={optimization} contradicts '
                f'feedback_filter={feedback_filter!r}')
        feedback_filter = feedback_filter or implied
    mode = from_env or feedback_filter or 'client'
    if mode not in MODES:
        source = f'environment variable {FEEDBACK_FILTER_ENV}' if from_env else 'feedback_filter'
        raise InvalidArgumentError(f'{source}={mode!r}: expected one of {", ".join(MODES)}')
    return mode


class ActionClient(CompatActionClient):
    """ROS Action client whose feedback subscription receives only its own goals' feedback."""

    def __init__(self, node: Node, action_type: Any, action_name: str, *,
                 feedback_filter: Optional[str] = None,
                 enable_feedback_msg_optimization: Optional[bool] = None,
                 writer_filtering: str = 'guarded',
                 **kwargs: Any) -> None:
        """
        Create an ActionClient.

        Takes every argument of :class:`rclpy.action.ActionClient`, plus ``feedback_filter``.

        :param node: The ROS node to add the action client to.
        :param action_type: Type of the action.
        :param action_name: Name of the action.
            Used as part of the underlying topic and service names.
        :param feedback_filter: How the feedback subscription is filtered:

            - ``'client'`` (default): on a random tag that starts the UUID of every goal this client
              sends with a feedback callback. The filter never changes after construction.
            - ``'goals'``: on the exact UUIDs of the live goals that have a feedback callback. The
              filter changes as goals come and go, which costs filter updates at the server.
            - ``'off'``: no filter, as plain rclpy.

            The environment variable ``CFT_ACTION_FEEDBACK_FILTER`` overrides it. Where the filter
            cannot be used, the client falls back to plain behaviour, logs why once, and reports
            it in :attr:`feedback_filter_state`.
        :param enable_feedback_msg_optimization: The name of the newer distros' opt-in feedback
            filter (rclpy 10, Lyrical), accepted so that code moves between distros: ``True``
            means ``feedback_filter='client'`` unless another filtering mode is given, ``False``
            means ``'off'``. Unlike there, filtering is on when neither is given.
        :param writer_filtering: Which servers may filter on their side. ``'guarded'`` (default):
            the filter uses the library's own filter class, which only a server run under
            ``cft-action guard`` knows; any other server sends this client all feedback, as to a
            plain client, and this client's DDS reader drops other goals' feedback before Python.
            ``'any'``: a DDS-SQL filter that every Fast DDS server evaluates, which costs an
            unguarded server time per sample and filtered client, and exposes it to
            Fast-DDS#4878 (docs/SAFETY.md). The environment variable
            ``CFT_ACTION_WRITER_FILTERING`` overrides it.
        :param kwargs: ``callback_group``, ``goal_service_qos_profile``,
            ``result_service_qos_profile``, ``cancel_service_qos_profile``,
            ``feedback_sub_qos_profile`` and ``status_sub_qos_profile``, as for rclpy.
        :raises ValueError: if ``feedback_filter``, ``writer_filtering`` or their environment
            variables name no known value, or ``enable_feedback_msg_optimization`` contradicts
            ``feedback_filter``.
        """
        mode = _resolve_mode(feedback_filter, enable_feedback_msg_optimization)
        self._writer_filtering = _resolve_writer_filtering(writer_filtering)
        self._cft_logger = PromptLogger(node.get_logger().get_child('cft_action'))
        self._mode = mode
        self._reader = FilteredReader(
            self._cft_logger, match_all=MATCH_ALL, uuid_class=self._writer_filtering == 'guarded',
            unfiltered='feedback filter not used, all feedback is received as with rclpy')
        self._logged_unguarded = False
        self._plan: Optional[GoalFilterPlan] = None  # None: the filter is not (or no longer) used
        self._install_ran = False
        self._finished: dict[bytes, float] = {}  # goal UUID -> when it finished
        self._last_activity = time.monotonic()
        self._logged_explicit_uuid = False
        self._feedback_drained_at = time.monotonic()  # last wait that found no feedback queued
        self._feedback_taken = 0
        self._feedback_dropped = 0
        # goal UUID -> source timestamp of its result response (server clock, ns; 0: unknown)
        self._result_stamps: dict[bytes, int] = {}
        # Where rcl's entities are. The result client is set only when both were found: feedback
        # and results are then taken here, with their sample info, instead of by rclpy.
        self._feedback_subscription_ptr: Optional[int] = None
        self._feedback_subscription_reason = ''
        self._result_client_ptr: Optional[int] = None
        self._feedback_support: Optional[_rcl.MessageSupport] = None
        self._result_support: Optional[_rcl.MessageSupport] = None
        self._resolved_action_name = ''
        # The proof of arrival of filter updates at the server (cft_action.arrival).
        self._confirmed_revision = 1  # the initial filter arrives with the reader itself
        self._held: list[_HeldGoal] = []
        self._arrival_probe: Optional[ServiceProbe] = None
        self._probe_revision = 0
        self._probe_polled_since: Optional[float] = None
        self._own_participant: Optional[bytes] = None
        self._held_goals = 0
        self._arrival_timeouts = 0
        self._cancel_qos = kwargs.get('cancel_service_qos_profile', qos_profile_services_default)
        self._install_before_first_wait(node, action_type, action_name, kwargs)
        self._release_timer = node.create_timer(
            RELEASE_CHECK_PERIOD, self._release_finished_goals, callback_group=self.callback_group)
        self._release_timer.cancel()
        self._arrival_timer = node.create_timer(
            ARRIVAL_POLL_PERIOD, self._poll_arrival, callback_group=self.callback_group)
        self._arrival_timer.cancel()

    # --- installation -----------------------------------------------------------------------------

    def _install_before_first_wait(self, node: Node, action_type: Any, action_name: str,
                                   kwargs: dict) -> None:
        """Run rclpy's constructor, installing the filter just before the node publishes us.

        rmw_fastrtps recreates the DataReader when a first filter is set, which must not happen
        while an executor waits on it, nor after a goal was sent, or queued feedback would be lost.
        Node.add_waitable is where an executor can first see this client, so the filter goes in
        there, after rclpy has created the rcl action client.
        """
        shadowed = node.__dict__.get('add_waitable')
        add_waitable = node.add_waitable

        def install_then_add(waitable) -> None:
            if waitable is self:
                self._resolved_action_name = node.resolve_topic_name(action_name)
                self._locate_entities(self._resolved_action_name)
                self._install_filter()
            add_waitable(waitable)

        node.add_waitable = install_then_add  # type: ignore[method-assign]
        try:
            super().__init__(node, action_type, action_name, **kwargs)
        finally:
            if shadowed is None:
                del node.add_waitable
            else:
                node.add_waitable = shadowed  # type: ignore[method-assign]
        if not self._install_ran:
            self._reader.fall_back('rclpy did not add the client through Node.add_waitable')

    def _locate_entities(self, resolved_action_name: str) -> None:
        """Find the feedback subscription and result client inside rcl's action client."""
        pointer = self._cft_client_handle.pointer
        self._feedback_subscription_ptr, self._feedback_subscription_reason = (
            _rcl.action_feedback_subscription(pointer, resolved_action_name))
        self._result_client_ptr, reason = _rcl.action_result_client(pointer, resolved_action_name)
        reason = reason or self._feedback_subscription_reason
        if reason:
            self._result_client_ptr = None
            self._cft_logger.warning(
                'feedback is taken as by rclpy and dropped once the goal result arrives, even '
                f'feedback the server published before the result: {reason}')
            return
        self._feedback_support = _rcl.MessageSupport(self._cft_action_type.Impl.FeedbackMessage)
        self._result_support = _rcl.MessageSupport(
            self._cft_action_type.Impl.GetResultService.Response)

    def _install_filter(self) -> None:
        self._install_ran = True
        if self._mode == 'off':
            self._reader.fall_back('feedback_filter is off', log=False)
            return
        if not is_content_filter_supported(self._cft_node):
            self._reader.fall_back('the rmw implementation has no content filter')
            return
        pointer = self._feedback_subscription_ptr
        if pointer is None:
            self._reader.fall_back(self._feedback_subscription_reason)
            return
        plan = GoalFilterPlan(self._mode)
        if self._reader.install(self._cft_client_handle, pointer,
                                f'{self._resolved_action_name}/_action/feedback',
                                ContentFilterOptions(plan.initial(), [])):
            self._plan = plan

    def _update(self, make_expression: Callable[[], Optional[str]]) -> None:
        """Change the filter in place; on failure, fall back to receiving all feedback."""
        try:
            expression = make_expression()
        except ExpressionTooLong as e:
            self._abandon_filter(f'a filter update failed: {e}')
            return
        if expression is not None:
            self._reader.update(ContentFilterOptions(expression, []))
            if self._reader.filter is None:
                self._plan = None

    def _abandon_filter(self, reason: str) -> None:
        self._plan = None
        self._reader.abandon(reason)

    # --- public API -------------------------------------------------------------------------------

    @property
    def feedback_filter_state(self) -> FeedbackFilterState:
        """The feedback filter's mode, whether it is active and why not, and its counters."""
        with self._reader.lock:
            common = self._reader.state
            return FeedbackFilterState(
                self._mode, common.active, common.reason, common.expression, common.updates,
                live_goals=self._plan.live_goals if self._plan else 0,
                feedback_taken=self._feedback_taken, feedback_dropped=self._feedback_dropped,
                confirmed=self._plan is None or self._needed_revision() <= self._confirmed_revision,
                held_goals=self._held_goals, arrival_timeouts=self._arrival_timeouts,
                filtered_in=self._filtered_in())

    def _filtered_in(self) -> str:
        """Where other goals' feedback is dropped; see :class:`FeedbackFilterState`."""
        if self._reader.filter is None:
            return 'none'
        if not self._reader.uuid_class:
            return 'writer'  # DDS-SQL: every Fast DDS writer filters (up to its reader limit)
        verdicts = self._reader.reader_verdicts
        if verdicts is None:
            return 'unknown'
        # A guarded writer marks what it sends, so the reader judges only the samples sent in
        # the moment between a filter change here and its arrival there; an unguarded one marks
        # nothing, and the reader judges every sample, other goals' included.
        if verdicts and verdicts >= self._feedback_taken:
            return 'reader'
        return 'writer' if self._feedback_taken else 'unknown'

    def _log_if_unguarded(self) -> None:
        """Say once that the server does not filter for this client, once there is evidence."""
        with self._reader.lock:
            if (self._filtered_in() != 'reader' or (self._reader.reader_verdicts or 0) < 10):
                return
            self._logged_unguarded = True
        self._cft_logger.info(
            "the action server's writer does not filter this client's feedback (the server does "
            "not run under 'cft-action guard'): other goals' feedback crosses the network to this "
            "client and its DDS reader drops it before Python. Under the guard the server would "
            'not send it (README, "What it saves")')

    def new_goal_uuid(self) -> UUID:
        """
        Return a fresh goal UUID that the feedback filter already matches.

        Use it for ``send_goal_async(goal_uuid=...)`` when the caller must know the id before
        sending: a UUID of one's own costs a filter update, this one does not.

        :return: In ``client`` mode a UUID that starts with this client's tag; in ``goals`` mode
            one already announced to the server; otherwise a random UUID.
        """
        with self._reader.lock:
            raw = self._plan.uuid_for_feedback() if self._plan else random_uuid4()
        return UUID(uuid=list(raw))

    def send_goal_async(self, goal: Any, feedback_callback: Optional[Callable] = None,
                        goal_uuid: Optional[UUID] = None) -> Future:
        """
        Send a goal and asynchronously get the result.

        The result of the returned Future is set to a ClientGoalHandle when receipt of the goal
        is acknowledged by an action server.

        When the filter must grow to match this goal, it grows before the request is sent, and
        the request is held until the server's cancel service, asked from a client created after
        the growth, has replied: discovery is ordered, so the feedback writer then has the new
        filter, and the feedback that the server publishes at once is not filtered out. Requests
        are sent in the order of the calls.

        :param goal: The goal request.
        :type goal: action_type.Goal
        :param feedback_callback: Callback function for feedback associated with the goal.
            A goal without one receives no feedback at all.
        :type feedback_callback: function
        :param goal_uuid: Universally unique identifier for the goal.
            If None, then a UUID that the feedback filter matches is generated.
        :type: unique_identifier_msgs.UUID
        :return: a Future instance to a goal handle that completes when the goal request
            has been accepted or rejected.
        :rtype: :class:`rclpy.task.Future` instance
        :raises: TypeError if the type of the passed goal isn't an instance of
          the Goal type of the provided action when the service was
          constructed.
        """
        if not isinstance(goal, self._cft_action_type.Goal):
            raise TypeError()
        with self._reader.lock:
            if goal_uuid is not None and feedback_callback is not None:
                self._forget_finished(bytes(goal_uuid.uuid))
            if self._plan is not None:
                if goal_uuid is None:
                    raw = (self._plan.uuid_for_feedback() if feedback_callback is not None
                           else self._plan.untagged_uuid())
                    goal_uuid = UUID(uuid=list(raw))
                if feedback_callback is not None:
                    self._watch(bytes(goal_uuid.uuid))
            revision = 0
            if self._plan is not None and goal_uuid is not None and feedback_callback is not None:
                revision = self._plan.revision_matching(bytes(goal_uuid.uuid))
            if goal_uuid is not None and (self._held or (
                    revision > self._confirmed_revision and self._feedback_writer_is_remote())):
                return self._hold(_HeldGoal(revision, goal, feedback_callback, goal_uuid,
                                            Future()))
            return super().send_goal_async(goal, feedback_callback, goal_uuid)

    def destroy(self) -> None:
        """Destroy the underlying action client handle."""
        self._cft_node.destroy_timer(self._release_timer)
        self._cft_node.destroy_timer(self._arrival_timer)
        with self._reader.lock:
            self._end_probe()
            self._reader.detach('the action client was destroyed')
        super().destroy()

    # --- proof of arrival of filter updates -------------------------------------------------------

    def _feedback_writer_is_remote(self) -> bool:
        """Whether a feedback writer that this client knows of is in another participant.

        Fast DDS does not filter in the writer within a participant, and a writer not discovered
        yet matches the reader with the filter in force; neither needs a proof.
        """
        topic = f'{self._resolved_action_name}/_action/feedback'
        if self._own_participant is None:
            self._own_participant = node_participant(self._cft_node, [topic])
            if self._own_participant is None:
                return True  # not seen ourselves yet: ask for the proof rather than guess
        return any(participant_of(info.endpoint_gid) != self._own_participant
                   for info in self._cft_node.get_publishers_info_by_topic(topic))

    def _needed_revision(self) -> int:
        return max((held.revision for held in self._held), default=0)

    def _hold(self, held: _HeldGoal) -> Future:
        self._held.append(held)
        self._held_goals += 1
        if self._arrival_probe is None:
            self._start_probe()
        return held.future

    def _start_probe(self) -> None:
        # A random goal id with a zero stamp asks to cancel that goal only, which no server has:
        # the reply is ERROR_UNKNOWN_GOAL_ID, and no cancel callback runs.
        request = CancelGoal.Request()
        request.goal_info.goal_id.uuid = list(random_uuid4())
        self._arrival_probe = ServiceProbe(
            self._cft_node, CancelGoal, f'{self._resolved_action_name}/_action/cancel_goal',
            request, self._cancel_qos)
        # Without a plan the filter was abandoned for one that matches everything, which this
        # probe, created after it, proves as well.
        self._probe_revision = (self._plan.revision if self._plan is not None
                                else self._needed_revision())
        self._probe_polled_since = None
        self._arrival_timer.reset()

    def _end_probe(self) -> None:
        if self._arrival_probe is not None:
            self._arrival_probe.destroy()
            self._arrival_probe = None

    def _poll_arrival(self) -> None:
        with self._reader.lock:
            probe = self._arrival_probe
            if probe is None:
                self._arrival_timer.cancel()
                return
            now = time.monotonic()
            if self._probe_polled_since is None:
                # From the first poll, not from the hold: a caller that sends a burst of goals
                # before it spins gives the probe no chance until then.
                self._probe_polled_since = now
            if probe.poll(now):
                self._confirmed_revision = max(self._confirmed_revision, self._probe_revision)
                self._end_probe()
                self._send_held(self._confirmed_revision)
            elif now - self._probe_polled_since >= FILTER_ARRIVAL_TIMEOUT:
                self._arrival_timeouts += 1
                if self._arrival_timeouts == 1:
                    self._cft_logger.warning(
                        f'the action server did not answer {probe.service_name} within '
                        f'{FILTER_ARRIVAL_TIMEOUT:g} s, so the arrival of a filter update is not '
                        'proven: held goals are sent without it, and the first feedback that the '
                        'server publishes for them may be lost')
                self._end_probe()
                self._send_held(self._needed_revision())
            else:
                return
            if self._held:
                self._start_probe()
            else:
                self._arrival_timer.cancel()

    def _send_held(self, up_to_revision: int) -> None:
        """Send the held requests, in order, up to the first one that needs a later revision."""
        while self._held and self._held[0].revision <= up_to_revision:
            held = self._held.pop(0)
            if held.future.cancelled():
                continue
            sent = super().send_goal_async(held.goal, held.feedback_callback, held.goal_uuid)
            _forward(sent, held.future)

    # --- goal bookkeeping -------------------------------------------------------------------------

    def _forget_finished(self, goal_uuid: bytes) -> None:
        """A new goal reuses this UUID: what the last one left is not its own."""
        self._finished.pop(goal_uuid, None)
        self._result_stamps.pop(goal_uuid, None)

    def _watch(self, goal_uuid: bytes) -> None:
        self._last_activity = time.monotonic()
        if self._plan is None or not self._plan.watch(goal_uuid):
            return
        if self._plan.mode == 'client' and not self._logged_explicit_uuid:
            self._logged_explicit_uuid = True
            self._cft_logger.info(
                "a goal_uuid without this client's tag is added to the feedback filter, which "
                'costs a filter update at the server; ActionClient.new_goal_uuid() avoids it')
        self._update(self._plan.grow)

    def _cft_result_request_done(self, future: Future) -> None:
        # rclpy drops a goal's feedback callback as soon as its result arrives, and so loses the
        # goal's feedback still queued behind the result (measured: 559 of 600 with 200 goals).
        # Here the goal counts as finished and is released after the grace period instead.
        goal_id = self._cft_forget_result_request(future)
        if goal_id is not None:
            self._note_finished([bytes(goal_id.uuid)])

    def is_ready(self, wait_set) -> bool:
        """Return True if one or more entities are ready in the wait set."""
        ready = super().is_ready(wait_set)
        if not self._cft_feedback_ready():
            self._feedback_drained_at = time.monotonic()
        return ready

    def take_data(self) -> dict:
        """Take stuff from lower level so the wait set doesn't immediately wake again.

        As rclpy's, except that the result response and the feedback are taken with their source
        timestamps, and feedback that the server published after its goal's result is dropped.
        """
        result_ready, feedback_ready = self._cft_take_readiness()
        if self._result_client_ptr is not None:
            # rclpy's takes drop the sample info: these two are taken below, with it.
            self._cft_clear_readiness()
        data = super().take_data()
        if 'result' in data:
            self._note_result(data['result'][0], 0)
        elif (result_ready and self._result_client_ptr is not None
              and self._result_support is not None):
            sequence_number, response, stamp = _rcl.take_response(
                self._result_client_ptr, self._result_support)
            if response is not None and sequence_number is not None:
                data['result'] = (sequence_number, response)
                self._note_result(sequence_number, stamp)
        stamp = 0
        # The supports exist exactly when both entities were found (_locate_entities).
        if (feedback_ready and self._feedback_subscription_ptr is not None
                and self._feedback_support is not None):
            feedback, stamp = _rcl.take_message(
                self._feedback_subscription_ptr, self._feedback_support)
            if feedback is not None:
                data['feedback'] = feedback
        feedback = data.get('feedback')
        if feedback is not None:
            self._feedback_taken += 1
            if not self._logged_unguarded and self._feedback_taken <= 100:
                self._log_if_unguarded()
            goal_uuid = bytes(feedback.goal_id.uuid)
            if (goal_uuid not in self._cft_feedback_callbacks
                    or self._published_after_result(goal_uuid, stamp)):
                self._feedback_dropped += 1
                del data['feedback']
        return data

    def _note_result(self, sequence_number: int, stamp: int) -> None:
        goal_id = self._cft_goal_id_of_result_request(sequence_number)
        if goal_id is None:
            return
        goal_uuid = bytes(goal_id.uuid)
        with self._reader.lock:
            if goal_uuid in self._cft_feedback_callbacks:
                # The first result answers the goal; a later request is answered later still.
                self._result_stamps.setdefault(goal_uuid, stamp)

    def _published_after_result(self, goal_uuid: bytes, stamp: int) -> bool:
        """Whether the server published this feedback after it sent the goal's result.

        Both timestamps come from the server's clock: it wrote the result response only after its
        execute callback had returned, so feedback published in there is stamped earlier.
        """
        with self._reader.lock:
            result_stamp = self._result_stamps.get(goal_uuid)
        if result_stamp is None:
            return False
        if not (result_stamp and stamp):
            return True  # no ordering evidence: as rclpy, which forgets the callback at the result
        return stamp > result_stamp

    async def execute(self, taken_data: dict) -> None:
        """Execute work after data has been taken from a ready wait set.

        As rclpy's, and it also notes goals that finished (rejected, succeeded, canceled or
        aborted), so that their callbacks and filter terms are released even if nobody asks for
        their results.
        """
        finished = []
        if 'goal' in taken_data:
            sequence_number, response = taken_data['goal']
            goal_id = self._cft_goal_id_of_goal_request(sequence_number)
            if goal_id is not None and not response.accepted:
                finished.append(bytes(goal_id.uuid))
        await super().execute(taken_data)
        if 'status' in taken_data:
            finished += [bytes(s.goal_info.goal_id.uuid) for s in taken_data['status'].status_list
                         if s.status in _TERMINAL]
        if finished:
            self._note_finished(finished)

    def _note_finished(self, goal_uuids: list[bytes]) -> None:
        now = time.monotonic()
        with self._reader.lock:
            new = [u for u in goal_uuids
                   if u in self._cft_feedback_callbacks and u not in self._finished]
            for goal_uuid in new:
                self._finished[goal_uuid] = now
            if new:
                self._last_activity = now
                if self._release_timer.is_canceled():
                    self._release_timer.reset()

    def _release_finished_goals(self) -> None:
        """Drop callbacks and filter terms of goals that finished a grace period ago."""
        now = time.monotonic()
        with self._reader.lock:
            for goal_uuid, finished_at in list(self._finished.items()):
                if (now - finished_at >= FINISHED_GOAL_GRACE
                        and finished_at < self._feedback_drained_at):
                    del self._finished[goal_uuid]
                    self._result_stamps.pop(goal_uuid, None)
                    self._cft_feedback_callbacks.pop(goal_uuid, None)
                    if self._plan is not None:
                        self._plan.finish(goal_uuid)
            # One shrink once every finished goal is released, not one per release check: each
            # update is an event at the server's writer.
            if (self._plan is not None and not self._finished
                    and now - self._last_activity >= RELEASE_CHECK_PERIOD):
                self._update(self._plan.shrink)
            if not self._finished and (self._plan is None or not self._plan.has_stale_terms()):
                self._release_timer.cancel()
