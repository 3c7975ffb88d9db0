# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""A node timer that runs only while it has work: created paused, resumed when work comes."""

from __future__ import annotations

from typing import Callable, Optional

from rclpy.callback_groups import CallbackGroup
from rclpy.node import Node

__all__ = ['PausedTimer']


class PausedTimer:
    """A timer of the owner's callback group, paused until :meth:`resume`.

    :param node: The node that owns the timer.
    :param period: Seconds between calls while it runs.
    :param callback: What it calls.
    :param callback_group: The owner's callback group.
    """

    def __init__(self, node: Node, period: float, callback: Callable[[], None],
                 callback_group: Optional[CallbackGroup]) -> None:
        self._node = node
        self._timer = node.create_timer(period, callback, callback_group=callback_group)
        self._timer.cancel()

    def resume(self) -> None:
        """Run, if paused; a running timer keeps its phase."""
        if self._timer.is_canceled():
            self._timer.reset()

    def pause(self) -> None:
        """Stop calling until the next :meth:`resume`."""
        self._timer.cancel()

    def destroy(self) -> None:
        """Destroy the timer."""
        self._node.destroy_timer(self._timer)
