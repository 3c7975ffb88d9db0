# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""What an action client's feedback filter must match, and when it must change: no ROS import.

Every change of the filter is an event at the server's writer, and such events can crash a Fast
DDS server (docs/INTERNALS.md section 10), so this planner is built to change the filter as rarely
as it can:

- ``client`` mode matches a random tag that starts every UUID this client generates. The filter is
  fixed for the life of the client; only caller-supplied UUIDs without the tag need an exact term.
- ``goals`` mode matches exact goal UUIDs. When it must grow, it also announces a reserve of UUIDs
  for the goals to come, so a burst of goals costs one update, and those goals are known to the
  server's writer well before their requests are sent.
- Finished goals are not removed at once: their terms are dropped with the next growth, or by
  :meth:`GoalFilterPlan.shrink` once the client has been idle for a while.

A filter expression travels to the server inside one RTPS discovery parameter, whose length is a
16-bit field: an expression too long for it never reaches the server's writer, silently
(docs/INTERNALS.md, section 6, measured). So UUIDs this client generated, which are random, are
matched on their first :data:`TERM_BYTES` bytes (about 100 characters a goal), caller-supplied
ones on all 16, and an expression over :data:`MAX_EXPRESSION_BYTES` is refused with
:class:`ExpressionTooLong`.
"""

from __future__ import annotations

import os
import uuid as uuid_module
from typing import Callable, Optional

from cft_action.errors import CftActionError, InvalidArgumentError
from cft_action.topics.filters import any_of, uuid_prefix_term

MODES = ('client', 'goals', 'off')
TAG_BYTES = 4
TERM_BYTES = 4
DEFAULT_RESERVE = 8
MAX_RESERVE = 64
MAX_EXPRESSION_BYTES = 60_000


class ExpressionTooLong(CftActionError, ValueError):
    """The filter expression would not fit into a discovery message."""


def random_uuid4() -> bytes:
    """16 random bytes with valid RFC 4122 version 4 and variant bits."""
    return uuid_module.uuid4().bytes


class GoalFilterPlan:
    """The set of UUID terms a feedback filter must match, and the expression for it.

    :param mode: ``'client'`` or ``'goals'``.
    :param tag: the client's tag, for ``client`` mode; drawn at random when omitted.
    :param reserve: how many UUIDs ``goals`` mode announces ahead of use, at least; with many live
        goals it announces as many as are live, up to :data:`MAX_RESERVE`, so that bursts of goals
        cost few updates.
    :param new_uuid: source of random UUID bytes (replaceable in tests).
    """

    def __init__(self, mode: str, *, tag: Optional[bytes] = None,
                 reserve: int = DEFAULT_RESERVE,
                 new_uuid: Callable[[], bytes] = random_uuid4) -> None:
        if mode not in ('client', 'goals'):
            raise InvalidArgumentError(f'no filter plan for mode {mode!r}')
        self.mode = mode
        self.tag = (tag or os.urandom(TAG_BYTES)) if mode == 'client' else None
        self._reserve_size = reserve if mode == 'goals' else 0
        self._new_uuid = new_uuid
        self._live: dict[bytes, bytes] = {}   # goal UUID -> the prefix its term matches
        self._reserved: list[bytes] = []      # generated UUIDs announced, not yet used
        self._applied: frozenset[bytes] = frozenset()  # prefixes in the expression in force
        self._added_in: dict[bytes, int] = {}  # prefix in force -> the revision that added it
        # The version of the latest expression: 0 for the initial one, n for the n-th update after
        # it. Applied one update each, it is the reader's update count (cft_action.topics.arrival).
        self.revision = -1
        self._generated: set[bytes] = set()   # UUIDs this plan drew itself, matched by prefix

    # --- UUIDs -----------------------------------------------------------------------------------

    def tagged_uuid(self) -> bytes:
        """A fresh UUID that starts with the tag (``client`` mode): it needs no term."""
        if self.tag is None:
            raise InvalidArgumentError("a 'goals' plan has no tag to start a UUID with")
        raw = bytearray(self._new_uuid())
        raw[:TAG_BYTES] = self.tag
        return bytes(raw)

    def untagged_uuid(self) -> bytes:
        """A fresh UUID that the filter does not match: for goals without a feedback callback."""
        while True:
            raw = self._new_uuid()
            if not self._matched(raw):
                return raw

    def uuid_for_feedback(self) -> bytes:
        """A fresh UUID for a goal with a feedback callback: tagged, or taken from the reserve."""
        if self.mode == 'client':
            return self.tagged_uuid()
        if self._reserved:
            return self._reserved.pop(0)
        return self._generated_uuid()

    def _generated_uuid(self) -> bytes:
        # Its short prefix must be unique among this client's terms, or finishing one goal would
        # drop the term of another.
        taken = set(self._live.values()) | {u[:TERM_BYTES] for u in self._reserved}
        while True:
            raw = self._new_uuid()
            if raw[:TERM_BYTES] not in taken and not self._matched(raw):
                self._generated.add(raw)
                return raw

    def _matched(self, goal_uuid: bytes) -> bool:
        if self.tag is not None and goal_uuid.startswith(self.tag):
            return True
        return any(goal_uuid.startswith(prefix) for prefix in self._applied)

    # --- goals -----------------------------------------------------------------------------------

    def needs_term(self, goal_uuid: bytes) -> bool:
        """Whether the filter needs a term for this goal to receive its feedback."""
        return self.tag is None or not goal_uuid.startswith(self.tag)  # no tag: 'goals' mode

    def watch(self, goal_uuid: bytes) -> bool:
        """Register a goal with a feedback callback; return True if the filter must grow first."""
        if not self.needs_term(goal_uuid):
            return False
        if goal_uuid in self._reserved:
            self._reserved.remove(goal_uuid)
        prefix = goal_uuid[:TERM_BYTES] if goal_uuid in self._generated else goal_uuid
        self._live[goal_uuid] = prefix
        return prefix not in self._applied

    def revision_matching(self, goal_uuid: bytes) -> Optional[int]:
        """The revision of the expression that first matched this goal, or None if none does.

        The initial expression (revision 0) reaches every writer with the reader itself; a later
        one travels by discovery, so a goal matched only by it must wait until the writer has it.
        """
        if self.tag is not None and goal_uuid.startswith(self.tag):
            return 0
        # A term is a generated UUID's first TERM_BYTES bytes, or a supplied UUID whole.
        return min((self._added_in[prefix] for prefix in (goal_uuid[:TERM_BYTES], goal_uuid)
                    if prefix in self._added_in), default=None)

    def finish(self, goal_uuid: bytes) -> None:
        """Forget a goal: its term is dropped with the next update or shrink."""
        self._live.pop(goal_uuid, None)
        self._generated.discard(goal_uuid)

    # --- expressions -----------------------------------------------------------------------------

    def grow(self) -> str:
        """The expression to apply now that the filter must grow; refills the reserve.

        :raises ExpressionTooLong: if even without a reserve the live goals do not fit.
        """
        target = min(MAX_RESERVE, max(self._reserve_size, len(self._live))) \
            if self._reserve_size else 0
        while len(self._reserved) < target:
            self._reserved.append(self._generated_uuid())
        try:
            return self._commit()
        except ExpressionTooLong:
            self._generated.difference_update(self._reserved)
            self._reserved.clear()
            return self._commit()

    def has_stale_terms(self) -> bool:
        """Whether the applied expression still matches goals that finished."""
        return not self._applied <= self._wanted()

    def shrink(self) -> Optional[str]:
        """The expression without finished goals, or None if there is nothing to drop."""
        if not self.has_stale_terms():
            return None
        return self._commit()

    def initial(self) -> str:
        """The expression installed once, when the client is created, reserve included."""
        return self.grow()

    def _wanted(self) -> frozenset[bytes]:
        return frozenset(self._live.values()) | {u[:TERM_BYTES] for u in self._reserved}

    def _commit(self) -> str:
        wanted = self._wanted()
        terms = [uuid_prefix_term(self.tag)] if self.tag is not None else []
        terms += [uuid_prefix_term(prefix) for prefix in sorted(wanted)]
        expression = any_of(terms)
        if len(expression.encode()) > MAX_EXPRESSION_BYTES:
            raise ExpressionTooLong(
                f'a filter over {len(wanted)} goals is {len(expression.encode())} bytes, over the '
                f'{MAX_EXPRESSION_BYTES} that fit into a discovery message')
        self.revision += 1
        self._added_in = {prefix: self._added_in.get(prefix, self.revision) for prefix in wanted}
        self._applied = wanted
        return expression

    @property
    def live_goals(self) -> int:
        """How many goals currently hold a term."""
        return len(self._live)
