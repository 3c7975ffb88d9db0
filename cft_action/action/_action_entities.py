# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The feedback and status subscriptions and result client inside rcl's action client, and takes.

rcl has no accessor for them, so they are found by layout and checked (docs/INTERNALS.md section
3). The action client filters the feedback subscription, and takes feedback and result responses
here rather than through rclpy, whose takes drop the sample info: the source timestamps tell
whether the server published a feedback message before or after the goal's result. Status is
taken by :mod:`cft_action.action._goal_status`.
"""

from __future__ import annotations

from typing import Any, Optional

from cft_action import _rcl
from cft_action._rclpy_compat import PromptLogger

__all__ = ['ActionEntities']


class ActionEntities:
    """The rcl entities of one action client that rclpy does not expose.

    :param client_pointer: The ``rcl_action_client_t *``.
    :param resolved_action_name: The fully qualified action name, after remapping.
    :param action_type: The action type.
    :param logger: For the one warning when they are not found.
    """

    def __init__(self, client_pointer: int, resolved_action_name: str, action_type: Any,
                 logger: PromptLogger) -> None:
        self.feedback_subscription, self.feedback_reason = _rcl.action_feedback_subscription(
            client_pointer, resolved_action_name)
        self.status_subscription, self.status_reason = _rcl.action_subscription(
            client_pointer, resolved_action_name, 'status')
        result_client, reason = _rcl.action_result_client(client_pointer, resolved_action_name)
        reason = reason or self.feedback_reason
        # Set only when both were found: feedback and results are then taken here.
        self.result_client: Optional[int] = None
        self._feedback_support: Optional[_rcl.MessageSupport] = None
        self._result_support: Optional[_rcl.MessageSupport] = None
        if reason:
            logger.warning(
                'feedback is taken as by rclpy and dropped once the goal result arrives, even '
                f'feedback the server published before the result: {reason}')
            return
        self.result_client = result_client
        self._feedback_support = _rcl.MessageSupport(action_type.Impl.FeedbackMessage)
        self._result_support = _rcl.MessageSupport(action_type.Impl.GetResultService.Response)

    @property
    def takes_here(self) -> bool:
        """Whether feedback and result responses are taken here, with their source timestamps."""
        return self.result_client is not None

    def take_result_into(self, data: dict) -> int:
        """Take a result response into ``data['result']`` as rclpy's take_data puts it,
        ``(sequence_number, response)``; return its source timestamp, or 0 if none came."""
        if self.result_client is None or self._result_support is None:
            return 0
        sequence_number, response, stamp = _rcl.take_response(self.result_client,
                                                               self._result_support)
        if response is None or sequence_number is None:
            return 0
        data['result'] = (sequence_number, response)
        return stamp

    def take_feedback(self) -> tuple[Optional[Any], int]:
        """``(feedback_message, source_timestamp)``; ``(None, 0)`` if none came."""
        if self.feedback_subscription is None or self._feedback_support is None:
            return None, 0
        return _rcl.take_message(self.feedback_subscription, self._feedback_support)
