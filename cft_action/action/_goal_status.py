# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The action client's status, taken with only its own goals' entries in Python.

An action server's ``GoalStatusArray`` lists every goal it holds, finished ones until its
``result_timeout``, and goes to every client at every transition of any goal. rclpy converts the
whole array to Python on every take and then looks each entry up among its goal handles, so a
client pays for every goal of every client. Here the sample is taken serialized and trimmed
natively (cft_action/native/reader/_status_trim.c) to the entries that can change one of this
client's goal handles: those of goals whose response has not been executed yet, and for goals with a
handle, each change of status once. rclpy's ``execute`` then sets exactly the statuses it would have
set from the whole array, since setting a handle's status again to the same value changes nothing
(docs/INTERNALS.md, "Status, trimmed to the client's goals").

The status subscription is found inside rcl's action client by layout and checked by its topic
name, as the feedback subscription is; where it is not found, status is taken by rclpy, whole.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple, Optional

from action_msgs.msg import GoalInfo, GoalStatus
from rclpy.serialization import deserialize_message

from cft_action import _rcl
from cft_action.action._action_entities import ActionEntities
from cft_action._rclpy_compat import PromptLogger
from cft_action.errors import ContentFilterError

__all__ = ['GoalStatusState', 'OwnGoalStatus']

_TERMINAL = frozenset({GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED,
                       GoalStatus.STATUS_ABORTED})


class GoalStatusState(NamedTuple):
    """What the status trim did, since the client was created.

    :ivar active: whether status samples are trimmed; when not, rclpy converts each whole.
    :ivar reason: why not; empty when active.
    :ivar filtered: whether the status reader also drops, before they wake the executor, the
        samples that can change none of this client's goal handles (when not, its filter could
        not be set: the log says why).
    :ivar samples: status samples taken and trimmed.
    :ivar entries: goal entries those samples listed.
    :ivar delivered: entries converted to Python and given to rclpy's ``execute``.
    :ivar prompt_acks: whether the status reader acknowledges a HEARTBEAT at once instead of
        Fast DDS's 5 ms later, which shortens what a guarded server owes it (when not, the log
        says why).
    """

    active: bool
    reason: str
    filtered: bool = False
    samples: int = 0
    entries: int = 0
    delivered: int = 0
    prompt_acks: bool = False


class OwnGoalStatus:
    """Takes an action client's status samples, trimmed to the entries of its own goals.

    :param entities: Where rcl's action client keeps its status subscription.
    :param action_type: The action type, whose ``GoalStatusMessage`` status samples are.
    :param goal_id_of_request: rclpy's goal id of a goal request's sequence number, or None.
    :param logger: For the one warning when status cannot be trimmed.
    """

    def __init__(self, entities: ActionEntities, action_type: Any,
                 goal_id_of_request: Callable[[int], Any], logger: PromptLogger) -> None:
        self._message_type = action_type.Impl.GoalStatusMessage
        self._goal_id_of_request = goal_id_of_request
        self.subscription, self.reason = entities.status_subscription, entities.status_reason
        self._table: Optional[_rcl.StatusTable] = None
        self._filtered = False
        self._prompt_acks = False
        self._logger = logger
        if self.reason:
            logger.warning('status is taken as by rclpy, every goal of the server converted to '
                           f'Python: {self.reason}')
            return
        self._table = _rcl.StatusTable()

    @property
    def takes_here(self) -> bool:
        """Whether status is taken here, trimmed; else rclpy takes it whole."""
        return self._table is not None

    @property
    def state(self) -> GoalStatusState:
        """Whether status is trimmed, and its counters."""
        if self._table is None:
            return GoalStatusState(False, self.reason)
        samples, entries, delivered, _ = self._table.counts()
        return GoalStatusState(True, '', self._filtered, samples, entries, delivered,
                               self._prompt_acks)

    def filter_reader(self) -> None:
        """Make the status reader drop samples that can change none of this client's goal handles:
        those that list no goal of this client whose response is pending, nor one whose status
        differs from the last sample that the reader passed
        (cft_action/native/reader/_status_trim.c).

        rmw_fastrtps recreates the DataReader for its first filter (docs/INTERNALS.md section 4),
        so this must run before any executor waits on the subscription. An unguarded server does
        not know the class and sends every sample, which this process's reader judges; a guarded
        one sends only those that change this client's goals, or that it owes it (section 20).
        The reader acknowledges at once, which shortens what such a server owes it
        (cft_action/native/reader/_status_acks.c). Where the class cannot be used (Fast DDS 3),
        the reader's USER_DATA asks a guarded Fast DDS 3.3+ server for the same samples instead.
        """
        if self._table is None or self.subscription is None:
            return
        if why := _rcl.filter_class_status():
            refused = _rcl.mark_own_goals_reader(self.subscription, status=True)
            self._logger.info(
                f'the status filter class cannot be used here ({why}): this client drops the '
                'entries of other goals' + (f', and {refused}' if refused else
                                            '; a guarded server (Fast DDS 3.3+) sends it only the '
                                            'samples that change its goals'))
            return
        acks = _rcl.status_acks_begin()
        try:
            _rcl.set_content_filter(self.subscription, self._table.filter_expression,
                                    filter_class=_rcl.STATUS_FILTER_CLASS)
        except ContentFilterError as error:
            self._logger.info('every status sample wakes the executor, which then drops the '
                              f'entries of other goals: {error}')
            return
        self._filtered = True
        acks = acks or _rcl.status_acks_end()
        self._prompt_acks = not acks
        if acks:
            self._logger.info('the status reader acknowledges 5 ms after a HEARTBEAT, as Fast DDS '
                              f'does, and a guarded server sends it more status: {acks}')

    def sending(self, goal_uuid: bytes) -> None:
        """A goal request is about to be sent: its status entries go to rclpy from now on."""
        if self._table is not None:
            self._table.sending(goal_uuid)

    def take_into(self, data: dict, ready: bool) -> None:
        """If ``ready``, take one status sample into ``data['status']``, as rclpy's ``take_data``:
        a ``GoalStatusArray`` of this client's entries; nothing when no sample came or it listed
        none that can change one of this client's goal handles. A goal response in ``data`` is
        executed before the status, and makes a goal handle that the status may already update."""
        if not ready or self._table is None or self.subscription is None:
            return
        goal = data.get('goal')
        goal_id = None if goal is None else self._goal_id_of_request(goal[0])
        responding = None if goal_id is None else bytes(goal_id.uuid)
        cdr, entries = self._table.take(self.subscription, responding,
                                        goal is not None and goal_id is None)
        if cdr is not None and entries != 0:
            # entries < 0: the sample was not plain CDR; it is converted whole, as rclpy does.
            data['status'] = deserialize_message(cdr, self._message_type)

    def executed(self, taken_data: dict, goal_id: Optional[Any]) -> tuple[list[bytes], Any]:
        """rclpy's ``execute`` has run on ``taken_data``: note its goal response, for the goal
        ``goal_id`` (looked up before, since rclpy forgets it).

        :return: ``(finished, early)``: the goals that finished (rejected, or with a terminal
            status in it), and, for a goal accepted now whose status came before its response
            (which then updated no handle), a ``GoalStatusArray`` with that status for rclpy's
            ``execute``, else None. The server may never send that status again: under the guard
            it sends this client only samples that change its goals.
        """
        finished, early = [], None
        if goal_id is not None and self._table is not None:
            accepted = bool(taken_data['goal'][1].accepted)
            status = self._table.responded(bytes(goal_id.uuid), accepted)
            if not accepted:
                finished.append(bytes(goal_id.uuid))
            elif status is not None:
                early = self._message_type(status_list=[GoalStatus(
                    goal_info=GoalInfo(goal_id=goal_id), status=status)])
        for sample in (taken_data.get('status'), early):
            if sample is not None:
                finished += [bytes(s.goal_info.goal_id.uuid) for s in sample.status_list
                             if s.status in _TERMINAL]
        return finished, early
