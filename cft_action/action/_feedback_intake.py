# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The action client's feedback as it is taken from rcl: counted, late feedback dropped, batched.

rclpy takes one feedback message per wake of the executor, and a wake costs the executor a
rebuild of its wait set in Python (about 0.2 ms each, measured with ``benchmarks/many_goals.py``
at 2,000 goals: 8,000 of the client's 11,600 wakes were one feedback message each). Where the
client's callback group runs one callback at a time, which is rclpy's default, a wake here takes
every feedback message that is queued, up to :data:`FEEDBACK_BATCH`, and ``execute`` calls their
callbacks one after the other, in the order they came: what the executor would have done over
that many wakes. In a reentrant group each wake takes one, as rclpy does, since there the
executor may run feedback callbacks side by side.
"""

from __future__ import annotations

from typing import Any, Callable, Iterable

from rclpy.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup

from cft_action.action._action_entities import ActionEntities
from cft_action.action._feedback_filter import FeedbackFilter
from cft_action.action._finished_goals import FinishedGoals

__all__ = ['FEEDBACK_BATCH', 'FeedbackIntake', 'MORE_FEEDBACK']

#: Feedback messages that one wake takes at most, in a mutually exclusive callback group.
FEEDBACK_BATCH = 64

#: The key of ``take_data``'s dictionary under which the feedback messages taken after the one
#: under ``'feedback'`` go, in order; for code that subclasses the client and reads ``take_data``.
MORE_FEEDBACK = 'cft_action.more_feedback'


class FeedbackIntake:
    """Takes an action client's feedback into ``take_data``'s dictionary.

    :param entities: Where the feedback subscription is taken with its sample info.
    :param finished_goals: Which goals' feedback goes to no callback any more.
    :param feedback_filter: For its one log line once the server's filtering is known.
    :param writers: The GIDs of the server's feedback writers, for that line.
    :param callback_group: The client's; a mutually exclusive one takes feedback in batches.
    """

    def __init__(self, entities: ActionEntities, finished_goals: FinishedGoals,
                 feedback_filter: FeedbackFilter, writers: Callable[[], Iterable[Any]],
                 callback_group: CallbackGroup) -> None:
        self._entities, self._finished = entities, finished_goals
        self._filter, self._writers = feedback_filter, writers
        self._batch = FEEDBACK_BATCH if isinstance(callback_group,
                                                   MutuallyExclusiveCallbackGroup) else 1
        self.taken = 0  # messages taken from rcl
        self.dropped = 0  # of those, messages given to no callback

    def take_into(self, data: dict, ready: bool) -> None:
        """Put the feedback to deliver into ``data``: the first under ``'feedback'``, as rclpy's
        ``take_data``, the rest for :meth:`more`. ``ready``: the subscription is ready and taken
        here; otherwise only a message that rclpy took into ``data`` (without its timestamp)."""
        taken = []
        if 'feedback' in data:
            taken.append((data.pop('feedback'), 0))
        elif ready:
            for _ in range(self._batch):
                message, stamp = self._entities.take_feedback()
                if message is None:
                    break
                taken.append((message, stamp))
        kept = [message for message, stamp in taken if self._delivers(message, stamp)]
        if kept:
            data['feedback'] = kept[0]
        if len(kept) > 1:
            data[MORE_FEEDBACK] = kept[1:]

    @staticmethod
    def more(data: dict) -> list[Any]:
        """Remove from ``data`` and return the messages after its ``'feedback'``, in order."""
        return data.pop(MORE_FEEDBACK, [])

    def _delivers(self, message: Any, stamp: int) -> bool:
        self.taken += 1
        self._filter.log_if_unguarded(self.taken, self._writers)
        if self._finished.dropped(bytes(message.goal_id.uuid), stamp):
            self.dropped += 1
            return False
        return True
