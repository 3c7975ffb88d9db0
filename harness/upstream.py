"""An emulation of the upstream (Rolling) feedback filter, for comparison only: not library code.

Upstream (rcl#1287, rclpy#1633, docs/INTERNALS.md section 12), with
``enable_feedback_msg_optimization``:

- the filter is ``(goal_id.uuid[0] = %0 AND ... goal_id.uuid[15] = %15) OR (... %16 ...)``: 16
  parameters per goal, goals OR-ed, each parameter one UUID byte in decimal;
- a goal is added when its goal response says it was accepted;
- it is removed on its result, or on a terminal status;
- removing the last goal sets ``""``; on the DDS side that recreates the DataReader;
- more than 100 parameters (a 7th goal), or any error, clears the filter to ``""`` and disables it
  for good.

This class does the same on a plain :class:`rclpy.action.ActionClient` of Jazzy, through
``cft_action._rcl`` on the feedback subscription inside the rcl action client. It changes the filter
only from ``execute``, in the executor's thread and therefore never while that executor waits on the
subscription: the recreation under a waiting executor is a use-after-free in rmw_fastrtps that
upstream has to lock against (the rclnodejs port did). Every change is an event at the server's
writer, so run it only against a server under the guard (``cft_action.guard``).
"""

from __future__ import annotations

from typing import Any, Optional

from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient as RclpyActionClient
from rclpy.node import Node

from cft_action import _rcl

#: The DDS limit on expression parameters, which upstream enforces.
MAX_PARAMETERS = 100
UUID_SIZE = 16

_TERMINAL = frozenset({GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED,
                       GoalStatus.STATUS_ABORTED})


def upstream_expression(goals: int) -> str:
    """The expression upstream generates for ``goals`` goals (parameters numbered globally)."""
    terms = [' AND '.join(f'goal_id.uuid[{j}] = %{i * UUID_SIZE + j}' for j in range(UUID_SIZE))
             for i in range(goals)]
    if len(terms) == 1:
        return terms[0]
    return '(' + ') OR ('.join(terms) + ')'


class UpstreamEquivalentActionClient(RclpyActionClient):
    """A plain rclpy ActionClient plus the upstream per-goal feedback filter.

    :ivar filter_sets: calls to ``rcl_subscription_set_content_filter``; each is an event at the
        server's writer.
    :ivar recreations: of those, the ones that recreate the DataReader (the first non-empty filter
        on an unfiltered reader, and every ``""``).
    :ivar disabled_reason: why the filter was disabled for good; empty while it is not.
    """

    def __init__(self, node: Node, action_type: Any, action_name: str, **kwargs: Any) -> None:
        """Create the client; takes the arguments of :class:`rclpy.action.ActionClient`."""
        super().__init__(node, action_type, action_name, **kwargs)
        self.filter_sets = 0
        self.recreations = 0
        self.disabled_reason = ''
        self._goals: list[bytes] = []  # the goal UUIDs in the filter, in parameter order
        self._filtered = False
        pointer, reason = _rcl.action_feedback_subscription(
            self._client_handle.pointer, node.resolve_topic_name(action_name))
        self._feedback_ptr: Optional[int] = pointer
        if pointer is None:
            self.disabled_reason = reason

    @property
    def filtered_goals(self) -> int:
        """How many goals the filter in force matches."""
        return len(self._goals)

    async def execute(self, taken_data: dict) -> None:
        """rclpy's execute, then the upstream filter bookkeeping for what was just taken."""
        # rclpy forgets these mappings once the futures complete, so read them first.
        accepted = removed = None
        if 'goal' in taken_data:
            sequence_number, response = taken_data['goal']
            goal_id = self._goal_sequence_number_to_goal_id.get(sequence_number)
            if goal_id is not None and response.accepted:
                accepted = bytes(goal_id.uuid)
        if 'result' in taken_data:
            goal_id = self._result_sequence_number_to_goal_id.get(taken_data['result'][0])
            if goal_id is not None:
                removed = [bytes(goal_id.uuid)]
        await super().execute(taken_data)
        if accepted is not None:
            self._add(accepted)
        if 'status' in taken_data:
            removed = (removed or []) + [
                bytes(s.goal_info.goal_id.uuid) for s in taken_data['status'].status_list
                if s.status in _TERMINAL]
        for goal_uuid in removed or ():
            self._remove(goal_uuid)

    # --- the upstream algorithm -----------------------------------------------------------------

    def _add(self, goal_uuid: bytes) -> None:
        if self.disabled_reason or goal_uuid in self._goals:
            return
        if (len(self._goals) + 1) * UUID_SIZE > MAX_PARAMETERS:
            self._disable('exceeded the maximum number of filter expression parameters (100)')
            return
        self._apply(self._goals + [goal_uuid])

    def _remove(self, goal_uuid: bytes) -> None:
        if self.disabled_reason or goal_uuid not in self._goals:
            return
        self._apply([g for g in self._goals if g != goal_uuid])

    def _apply(self, goals: list[bytes]) -> None:
        expression = upstream_expression(len(goals)) if goals else ''
        parameters = [str(b) for goal in goals for b in goal]
        try:
            self._set(expression, parameters)
        except _rcl.ContentFilterError as e:
            self._disable(f'setting the filter failed: {e}')
            return
        self._goals = goals

    def _disable(self, reason: str) -> None:
        # Upstream clears the filter to "" on any error and never filters again.
        self.disabled_reason = reason
        self._goals = []
        if self._filtered:
            try:
                self._set('', [])
            except _rcl.ContentFilterError:
                pass  # as upstream: it only records the error

    def _set(self, expression: str, parameters: list[str]) -> None:
        # Only reached while not disabled, and a client without the subscription is disabled.
        assert self._feedback_ptr is not None
        with self._client_handle:
            _rcl.set_content_filter(self._feedback_ptr, expression, parameters)
        self.filter_sets += 1
        # rmw_fastrtps recreates the DataReader when the filter switches between "" and not "".
        if self._filtered != bool(expression):
            self.recreations += 1
        self._filtered = bool(expression)
