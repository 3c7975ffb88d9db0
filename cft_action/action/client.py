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
from typing import Any, Callable, Optional

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from unique_identifier_msgs.msg import UUID

from cft_action import _rcl
from cft_action.action._action_entities import ActionEntities
from cft_action.action._feedback_filter import FeedbackFilter, FeedbackFilterState
from cft_action.action._feedback_intake import FeedbackIntake, MORE_FEEDBACK, feedback_period
from cft_action.topics._filtered_reader import (filter_class_for, WRITER_FILTERING,
                                                WRITER_FILTERING_ENV)
from cft_action.action._finished_goals import FinishedGoals
from cft_action.action._goal_status import GoalStatusState, OwnGoalStatus
from cft_action.action._held_goals import cancel_goal_probe, HeldGoal, HeldGoals
from cft_action.action._own_responses import OwnResponses, ResponseFilterState
from cft_action._rclpy_compat import CompatActionClient, PromptLogger
from cft_action.topics.arrival import ArrivalGate, RemotePublishers
from cft_action.errors import InvalidArgumentError
from cft_action.action.goal_filter import MODES
from cft_action.topics.subscription import is_content_filter_supported

__all__ = ['ActionClient', 'FeedbackFilterState', 'FEEDBACK_FILTER_ENV', 'GoalStatusState',
           'MORE_FEEDBACK', 'ResponseFilterState', 'WRITER_FILTERING_ENV', 'WRITER_FILTERING']

#: Environment variable with which operators override the ``feedback_filter`` argument.
FEEDBACK_FILTER_ENV = 'CFT_ACTION_FEEDBACK_FILTER'

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

#: Depth of the goal, result and cancel services' queues of a client created without a profile for
#: them (rclpy's is 10). rmw_fastrtps delivers each response of an action's service to the response
#: reader of every client, which keeps the last N of all of them, so at 10 a client that lags behind
#: the others loses its own responses among theirs, and those goals never complete (README,
#: "Differences from rclpy"). Queued samples cost memory only while they wait to be taken.
SERVICE_QUEUE_DEPTH = 1000

#: Seconds between polls of the arrival probe while goal requests are held.
ARRIVAL_POLL_PERIOD = 0.01

#: Seconds between polls of the proof that goes on in the background after one timed out, while
#: goals are sent without holds; each poll resends the probe's request while it is unanswered. A
#: server that has not matched the probe's response reader takes the request, runs its cancel
#: callback and drops the reply after waiting up to 100 ms for the match (rmw_fastrtps), in its
#: executor: at 0.5 s, 32 clients whose proofs timed out sent an unguarded rclpy server 313
#: requests during 27 s of feedback (docs/BENCHMARKS.md, "The unguarded server's CPU").
BACKGROUND_PROOF_POLL_PERIOD = 5.0


def _deep_service_queues(kwargs: dict[str, Any]) -> dict[str, Any]:
    """``kwargs`` with a profile of ``SERVICE_QUEUE_DEPTH`` for each service not given one."""
    deep = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=SERVICE_QUEUE_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    return {**{f'{service}_service_qos_profile': deep for service in ('goal', 'result', 'cancel')},
            **kwargs}


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
                 feedback_filter: Optional[str] = None, writer_filtering: str = 'guarded',
                 enable_feedback_msg_optimization: Optional[bool] = None,
                 feedback_max_rate: Optional[float] = None, **kwargs: Any) -> None:
        """
        Create an ActionClient.

        Takes every argument of :class:`rclpy.action.ActionClient`, plus the filter's.
        :param node: The ROS node to add the action client to.
        :param action_type: Type of the action.
        :param action_name: Name of the action.
            Used as part of the underlying topic and service names.
        :param feedback_filter: ``'client'`` (default): on a random tag that starts the UUID of
            every goal sent with a feedback callback; ``'goals'``: on the live goals' UUIDs (an
            event at the server per change); ``'off'``: as rclpy. ``CFT_ACTION_FEEDBACK_FILTER``
            overrides it. Where the filter cannot be used, the client behaves as rclpy, logs why
            once, and says so in :attr:`feedback_filter_state`.
        :param enable_feedback_msg_optimization: rclpy 10's (Lyrical) name for its opt-in filter:
            ``True`` means ``'client'`` unless another mode is given, ``False`` means ``'off'``.
        :param writer_filtering: ``'guarded'`` (default): the library's filter class, which only
            a server under ``cft-action guard`` evaluates (elsewhere this client's DDS reader drops
            others' feedback); ``'any'``: DDS-SQL, which every Fast DDS server evaluates, at a
            cost and exposed to Fast-DDS#4878 (docs/SAFETY.md). ``CFT_ACTION_WRITER_FILTERING``.
        :param feedback_max_rate: At most this many feedback messages a second of each goal reach
            its callback, the first after each period (decided in this client); None: all.
        :param kwargs: ``callback_group``, ``feedback_sub_qos_profile``, ``status_sub_qos_profile``
            as for rclpy; ``goal_``, ``result_`` and ``cancel_service_qos_profile`` too, which
            default to a depth of ``SERVICE_QUEUE_DEPTH`` (rclpy's: 10).
        :raises ValueError: if ``feedback_filter``, ``writer_filtering`` or their environment
            variables name no known value, ``enable_feedback_msg_optimization`` contradicts
            ``feedback_filter``, or ``feedback_max_rate`` is not above 0.
        """
        mode = _resolve_mode(feedback_filter, enable_feedback_msg_optimization)
        self._feedback_period = feedback_period(feedback_max_rate)
        self._cft_logger = PromptLogger(node.get_logger().get_child('cft_action'))
        self._filter = FeedbackFilter(
            self._cft_logger, mode,
            filter_class=filter_class_for(writer_filtering, _rcl.UUID_FILTER_CLASS))
        self._reader = self._filter.reader
        self._cft_action_name = action_name
        services = _deep_service_queues(kwargs)
        # The arrival probe's cancel client takes the cancel service's (deep) profile.
        self._cancel_qos = services['cancel_service_qos_profile']
        self._responses = OwnResponses(self._cft_logger)
        with self._responses.filtering():
            super().__init__(node, action_type, action_name, request_lock=self._reader.lock,
                             **services)  # _cft_before_first_wait
        if not self._filter.installed:
            self._reader.fall_back('rclpy did not add the client through Node.add_waitable')
            self._assemble()

    def _cft_before_first_wait(self) -> None:
        # The first filter recreates the DataReader (rmw_fastrtps), which must not happen under a
        # waiting executor or after a goal was sent: so it goes in here, before the first wait.
        self._assemble()
        self._status.filter_reader()
        self._filter.install(self._cft_client_handle, self._entities.feedback_subscription,
                             f'{self._resolved_action_name}/_action/feedback',
                             self._entities.feedback_reason,
                             is_content_filter_supported(self._cft_node))
        if self._filter.plan is not None:
            # The proof begins now: the server discovers its probe with the recreated reader.
            with self._reader.lock:
                self._arrival.begin(0)

    def _assemble(self) -> None:
        """Create the parts that an executor uses, once rclpy has made the rcl action client."""
        node, lock = self._cft_node, self._reader.lock
        self._resolved_action_name = node.resolve_topic_name(self._cft_action_name)
        self._entities = ActionEntities(self._cft_client_handle.pointer,
                                        self._resolved_action_name, self._cft_action_type,
                                        self._cft_logger)
        self._status = OwnGoalStatus(self._entities, self._cft_action_type,
                                     self._cft_goal_id_of_goal_request, self._cft_logger)
        self._cft_goal_sending = self._status.sending
        feedback_topic = f'{self._resolved_action_name}/_action/feedback'
        self._feedback_writers = RemotePublishers(node, feedback_topic, [feedback_topic])
        cancel_service = f'{self._resolved_action_name}/_action/cancel_goal'
        probe = cancel_goal_probe(cancel_service, self._cancel_qos)
        # The feedback reader is recreated with the first filter, after the goal service's
        # endpoints: until a proof, a goal round trip does not show that the server has it.
        self._arrival = ArrivalGate(node, lambda: probe, lock, proven=-1)
        self._held_goals = HeldGoals(
            node, self.callback_group, self._arrival, lock, super().send_goal_async,
            lambda: self._reader.updates, self._cft_logger, cancel_service,
            timeout=FILTER_ARRIVAL_TIMEOUT, poll_period=ARRIVAL_POLL_PERIOD,
            background_poll_period=BACKGROUND_PROOF_POLL_PERIOD)
        self._finished_goals = FinishedGoals(
            node, self.callback_group, lock, self._cft_feedback_callbacks, self._filter.release,
            grace=FINISHED_GOAL_GRACE, period=RELEASE_CHECK_PERIOD)
        self._intake = FeedbackIntake(self._entities, self._finished_goals, self._filter,
                                      self._feedback_writers.gids, self.callback_group,
                                      self._feedback_period)

    # --- public API -------------------------------------------------------------------------------

    @property
    def feedback_filter_state(self) -> FeedbackFilterState:
        """The feedback filter's mode, whether it is active and why not, and its counters."""
        with self._reader.lock:
            return self._filter.state(
                self._intake.taken, self._intake.dropped, self._feedback_writers.gids,
                **self._held_goals.proof_state(self._filter.plan is not None))

    @property
    def goal_status_state(self) -> GoalStatusState:
        """Whether status samples reach Python trimmed to this client's goals, and counters."""
        return self._status.state

    @property
    def response_filter_state(self) -> ResponseFilterState:
        """Whether other clients' goal, cancel and result responses are dropped before Python."""
        return self._responses.state

    def new_goal_uuid(self) -> UUID:
        """
        Return a fresh goal UUID that the feedback filter already matches.

        Use it for ``send_goal_async(goal_uuid=...)`` when the caller must know the id before
        sending: a UUID of one's own costs a filter update, this one does not.

        :return: In ``client`` mode a UUID that starts with this client's tag; in ``goals`` mode
            one already announced to the server; otherwise a random UUID.
        """
        with self._reader.lock:
            return UUID(uuid=list(self._filter.new_goal_uuid()))

    def send_goal_async(self, goal: Any, feedback_callback: Optional[Callable] = None,
                        goal_uuid: Optional[UUID] = None) -> Future:
        """
        Send a goal and asynchronously get the result.

        The result of the returned Future is set to a ClientGoalHandle when receipt of the goal
        is acknowledged by an action server.

        A request whose goal the filter does not match yet is held until the server has the
        grown filter, proven by a reply of its cancel service to a probe created after the growth
        (discovery is ordered), so that feedback published at once is not filtered out; so is the
        first goal with a feedback callback, until the server has this client's feedback reader.
        Requests are sent in the order of the calls.

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
            if goal_uuid is None:
                raw = self._filter.uuid_for(feedback_callback is not None)
                goal_uuid = None if raw is None else UUID(uuid=list(raw))
            version = -1  # a goal without feedback waits for no proof
            if goal_uuid is not None and feedback_callback is not None:
                self._finished_goals.sent(bytes(goal_uuid.uuid))
                version = self._filter.watch(bytes(goal_uuid.uuid))
            if goal_uuid is not None and self._held_goals.must_hold(version,
                                                                    self._feedback_writers.any):
                return self._held_goals.hold(HeldGoal(version, goal, feedback_callback, goal_uuid,
                                                      Future()))
            return super().send_goal_async(goal, feedback_callback, goal_uuid)

    def wait_for_server(self, timeout_sec: Optional[float] = None) -> bool:
        """
        Wait for an action server to be ready.

        As rclpy, once the server's services are available; with a feedback filter, also once
        its feedback writer is proven to have this client's reader (as for a held goal), waiting
        for that at most ``FILTER_ARRIVAL_TIMEOUT`` seconds, within ``timeout_sec``.

        :param timeout_sec: Number of seconds to wait until an action server is available.
            If None, then wait indefinitely.
        :return: True if an action server is available, False if the timeout is exceeded.
        """
        started = time.monotonic()
        if not super().wait_for_server(timeout_sec=timeout_sec):
            return False
        if self._filter.plan is not None:
            self._held_goals.await_server_proof(self._feedback_writers, timeout_sec, started)
        return True

    def destroy(self) -> None:
        """Destroy the underlying action client handle."""
        self._finished_goals.destroy()
        self._held_goals.destroy()
        with self._reader.lock:
            self._reader.detach('the action client was destroyed')
        super().destroy()

    # --- rclpy's waitable, with late feedback and finished goals ----------------------------------

    def _cft_result_request_done(self, future: Future) -> None:
        # rclpy drops the feedback callback at the result (559 of 600 lost with 200 goals): later.
        goal_id = self._cft_forget_result_request(future)
        if goal_id is not None:
            self._finished_goals.finished([bytes(goal_id.uuid)])

    def is_ready(self, wait_set) -> bool:
        """Return True if one or more entities are ready in the wait set."""
        ready = super().is_ready(wait_set)
        if not self._cft_feedback_ready():
            self._finished_goals.drained()
        return ready

    def _cft_take_data(self) -> dict:
        """As rclpy's take_data, with the result and feedback's source timestamps, feedback after
        its goal's result (or over ``feedback_max_rate``) dropped, and status trimmed to the
        entries that can change this client's goal handles."""
        result_ready, feedback_ready = self._cft_take_readiness()
        status_ready = self._status.takes_here and self._cft_claim_status()
        entities = self._entities if self._entities.takes_here else None
        if entities is not None:
            self._cft_clear_readiness()  # rclpy's takes drop the sample info: taken below, with it
        data = super()._cft_take_data()
        taken_here = 'result' not in data and result_ready and entities is not None
        stamp = entities.take_result_into(data) if taken_here and entities else 0
        if 'result' in data:
            goal_id = self._cft_goal_id_of_result_request(data['result'][0])
            if goal_id is not None:
                self._finished_goals.result(bytes(goal_id.uuid), stamp)
        self._intake.take_into(data, feedback_ready and entities is not None)
        self._status.take_into(data, status_ready)
        return data

    async def execute(self, taken_data: dict) -> None:
        """Execute work after data has been taken from a ready wait set.

        As rclpy's, with every feedback message taken in this wake; notes finished goals."""
        goal_id = self._cft_goal_id_of_goal_request(taken_data.get('goal', (None,))[0])
        more = self._intake.more(taken_data)
        await super().execute(taken_data)
        for feedback in more:
            await super().execute({'feedback': feedback})
        finished, early = self._status.executed(taken_data, goal_id)
        if early is not None:  # the goal's status came before its response: its handle takes it
            await super().execute({'status': early})
        self._finished_goals.finished(finished)
