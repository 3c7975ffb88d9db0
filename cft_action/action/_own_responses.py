# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The action client's goal, cancel and result responses: other clients' never wake it.

A server's response writer sends each response to every client of the service, and rmw_fastrtps
discards those for other clients only when the executor, woken by them, takes them. The response
readers of rcl's action client get a filter of the library's as rclpy creates them
(cft_action/native/reader/_response_filter.c): it drops, in DDS's receive thread, each response
whose related sample identity names another participant, a subset of what rmw's take discards, so
the client gets exactly the responses it got before (docs/INTERNALS.md section 23).
"""

from __future__ import annotations

import contextlib
from typing import Iterator, NamedTuple, Optional

from cft_action import _rcl
from cft_action._rclpy_compat import PromptLogger

__all__ = ['OwnResponses', 'ResponseFilterState']

#: rcl's action client has three service clients: goal, cancel and result.
SERVICE_CLIENTS = 3


class ResponseFilterState(NamedTuple):
    """Whether other clients' service responses are dropped before they wake the executor.

    :ivar active: whether each of the action client's response readers has the filter.
    :ivar reason: why not; empty when active. Without it, rmw_fastrtps discards other clients'
        responses after each has woken the executor, as for a plain rclpy client.
    :ivar dropped: responses for other clients the readers dropped.
    :ivar passed: responses they passed: this client's, and those whose target they cannot tell.
    """

    active: bool
    reason: str
    dropped: int = 0
    passed: int = 0


class OwnResponses:
    """The response filter of one action client.

    :param logger: For the one message when the filter cannot be used.
    """

    def __init__(self, logger: PromptLogger) -> None:
        self._logger = logger
        self._filter: Optional[int] = None
        self._reason = 'the action client was not created'

    @contextlib.contextmanager
    def filtering(self) -> Iterator[None]:
        """Filter the response readers that rclpy creates in this block, on this thread."""
        reason = _rcl.response_filter_begin()
        try:
            yield
        finally:
            if not reason:
                self._filter, readers, refused = _rcl.response_filter_end()
                # The arrival probe's cancel client, created in the block too, may add one.
                if refused or readers < SERVICE_CLIENTS:
                    reason = refused or (f'{readers} response readers were created, not '
                                         f'{SERVICE_CLIENTS}')
            self._reason = reason
            if reason:
                self._logger.info('other clients\' goal, cancel and result responses wake the '
                                  f'executor, which drops them, as rclpy does: {reason}')

    @property
    def state(self) -> ResponseFilterState:
        """Whether the filter is in place, and its counters."""
        dropped, passed = (0, 0) if self._filter is None else (
            _rcl.response_filter_counts(self._filter))
        return ResponseFilterState(not self._reason, self._reason, dropped, passed)
