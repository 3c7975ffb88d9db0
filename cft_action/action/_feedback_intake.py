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

With ``feedback_max_rate`` each goal's feedback passes at most once per period, decided here, in
the client: the first message taken after the period passes, the others go to no callback.
"""

from __future__ import annotations

import time
from typing import Any, Callable, Iterable, Optional

from rclpy.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup

from cft_action.action._action_entities import ActionEntities
from cft_action.action._feedback_filter import FeedbackFilter
from cft_action.action._finished_goals import FinishedGoals
from cft_action.topics.rate import check_max_rate

__all__ = ['FEEDBACK_BATCH', 'FeedbackIntake', 'MORE_FEEDBACK', 'feedback_period']

#: Feedback messages that one wake takes at most, in a mutually exclusive callback group.
FEEDBACK_BATCH = 64

#: The key of ``take_data``'s dictionary under which the feedback messages taken after the one
#: under ``'feedback'`` go, in order; for code that subclasses the client and reads ``take_data``.
MORE_FEEDBACK = 'cft_action.more_feedback'

#: Goals whose next pass time is kept before the ones in the past are forgotten.
_RATE_GOALS_KEPT = 1024


def feedback_period(feedback_max_rate: Optional[float]) -> Optional[float]:
    """The seconds between two feedback messages of a goal for ``feedback_max_rate`` (Hz).

    :raises InvalidArgumentError: unless it is None or a finite number above 0.
    """
    rate = check_max_rate(feedback_max_rate, 'feedback_max_rate')
    return None if rate is None else 1.0 / rate


class FeedbackIntake:
    """Takes an action client's feedback into ``take_data``'s dictionary.

    :param entities: Where the feedback subscription is taken with its sample info.
    :param finished_goals: Which goals' feedback goes to no callback any more.
    :param feedback_filter: For its one log line once the server's filtering is known.
    :param writers: The GIDs of the server's feedback writers, for that line.
    :param callback_group: The client's; a mutually exclusive one takes feedback in batches.
    :param period: At least this many seconds between two messages of a goal that pass
        (:func:`feedback_period`); None: every message passes.
    """

    def __init__(self, entities: ActionEntities, finished_goals: FinishedGoals,
                 feedback_filter: FeedbackFilter, writers: Callable[[], Iterable[Any]],
                 callback_group: CallbackGroup, period: Optional[float] = None) -> None:
        self._entities, self._finished = entities, finished_goals
        self._filter, self._writers = feedback_filter, writers
        self._batch = FEEDBACK_BATCH if isinstance(callback_group,
                                                   MutuallyExclusiveCallbackGroup) else 1
        self.taken = 0  # messages taken from rcl
        self.dropped = 0  # of those, messages given to no callback
        self._period = period
        self._next_pass: dict[bytes, float] = {}  # goal UUID -> monotonic time

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
        goal = bytes(message.goal_id.uuid)
        if self._finished.dropped(goal, stamp) or not self._rate_passes(goal):
            self.dropped += 1
            return False
        return True

    def _rate_passes(self, goal: bytes) -> bool:
        if self._period is None:
            return True
        now = time.monotonic()
        if now < self._next_pass.get(goal, now):
            return False
        if len(self._next_pass) >= _RATE_GOALS_KEPT and goal not in self._next_pass:
            self._next_pass = {g: t for g, t in self._next_pass.items() if t > now}
        self._next_pass[goal] = now + self._period
        return True
