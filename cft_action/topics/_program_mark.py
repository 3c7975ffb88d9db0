# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""A reader's program mark: how a subscription asks guarded Fast DDS 3.3+ writers to filter for it
where the library's filter classes cannot be its content filter.

On Fast DDS 2.14 the rate and node classes are content filters that guarded writers evaluate. On
Fast DDS 3 no class of the library's can be a reader's content filter; instead the reader's
USER_DATA carries the program (``cft_action=program:<class> <expression>;``,
``cft_action/native/_filter_class.h``), and a writer in a process run under ``cft-action guard``
applies it to that reader (``cft_action/native/guard/_guard_programs.c``). An unguarded writer
ignores it. The owner still applies the same rule in its own process, so that what a writer
does not filter, or filters with a program it has not replaced yet, changes nothing.

A change travels by discovery (``DataReader::set_qos`` sends the reader's data again), and a
guarded writer reads its readers' marks again within ``REREAD_S`` of its arrival, at its next
write: until then it applies the previous program.
"""

from __future__ import annotations

from typing import Any, ContextManager, Iterable, Optional

from rclpy.subscription import Subscription

from cft_action import _rcl

__all__ = ['ProgramMark', 'REREAD_S']

#: How long after a mark's arrival a guarded writer may still apply the previous one, at most:
#: its routing rereads every reader's mark every CFT_FASTDDS3_REREAD_MS (0.2 s), and looks at its
#: readers at most every PROGRAM_LOOKUP_MS (0.05 s) (native/guard/).
REREAD_S = 0.25


class ProgramMark:
    """The program mark of one subscription's reader, once it carries one.

    :param handle: what keeps ``pointer`` alive while it is held (an rclpy handle).
    :param pointer: the ``rcl_subscription_t *``.
    :param filter_class: the library's class of the program (``_rcl.RATE_FILTER_CLASS`` or
        ``_rcl.NODE_FILTER_CLASS``).
    """

    def __init__(self, handle: ContextManager[Any], pointer: int, filter_class: str) -> None:
        self._handle, self._pointer, self._class = handle, pointer, filter_class
        self.expression = ''
        self.updates = 0  # changes after the first mark

    @classmethod
    def install(cls, subscription: Subscription, filter_class: str,
                expression: str) -> tuple[Optional[ProgramMark], str]:
        """Mark ``subscription``'s reader with its first program: the mark, or None and why not."""
        with subscription.handle:
            pointer = subscription.handle.pointer
        mark = cls(subscription.handle, pointer, filter_class)
        why = mark._set(expression)
        return (None, why) if why else (mark, '')

    def change(self, expression: str) -> str:
        """Make the mark ``expression`` if it differs; return why it could not be, or ``''``."""
        if expression == self.expression:
            return ''
        why = self._set(expression)
        if not why:
            self.updates += 1
        return why

    def _set(self, expression: str) -> str:
        with self._handle:
            why = _rcl.mark_reader_program(self._pointer, self._class, expression)
        if not why:
            self.expression = expression
        return why

    def routes(self, gid: bytes) -> Optional[bool]:
        """Whether the writer ``gid`` applies the mark (a guarded Fast DDS 3.3+ writer); None when
        the reader does not match it."""
        with self._handle:
            return _rcl.writer_marked(self._pointer, gid)

    def all_route(self, gids: Iterable[bytes]) -> bool:
        """Whether there are writers among ``gids`` and each applies the mark."""
        routed = [self.routes(bytes(gid)) for gid in gids]
        return bool(routed) and all(routed)
