# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""A timer that runs only while it has work, and that no thread can race its executor over.

An rclpy timer of the node cannot be paused safely under a multithreaded executor: the executor
marks a ready timer in one thread and calls it (``rcl_timer_call``) later in a worker, so a
``cancel()`` from any other thread in between makes rclpy 7.1 raise ``RCLError: failed to call
timer: timer is canceled`` into the executor. The exception ends the spin, or, where the executor
keeps going, leaves that timer marked as taken for good, so it never runs again (measured: client
processes died, and goals whose requests that timer was holding never completed). Destroying the
timer instead has the same kind of window in the executor's readiness check.

So the timer here is not the node's: it is an rcl timer inside a :class:`rclpy.waitable.Waitable`
of its own, which the executor waits on but never calls. Whether it fired is decided in
:meth:`PausedTimer.take_data` under the timer's own lock, where :meth:`pause` and
:meth:`resume` take it too, so a pause can only keep a firing from being taken, never break one.
A waitable also never runs twice at once, which a node timer in a reentrant callback group can.
It runs on the steady clock, so that a node on simulated time does not stall it.
"""

from __future__ import annotations

import threading
from typing import Any, Callable, Optional

from rclpy.callback_groups import CallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.timer import Timer
from rclpy.waitable import NumberOfEntities, Waitable

__all__ = ['PausedTimer']


class PausedTimer(Waitable):
    """A timer in the owner's callback group, paused until :meth:`resume`.

    :param node: The node whose executors run it.
    :param period: Seconds between calls while it runs.
    :param callback: What it calls, from the executor, with no arguments.
    :param callback_group: The owner's callback group.
    """

    def __init__(self, node: Node, period: float, callback: Callable[[], None],
                 callback_group: CallbackGroup) -> None:
        super().__init__(callback_group)
        self._node = node
        self._callback = callback
        self._lock = threading.Lock()
        self._destroyed = False
        self._index: Optional[int] = None  # in the wait set the executor is waiting on
        # Not the node's: no executor sees it but through this waitable, nor calls its callback.
        self._timer = Timer(callback, callback_group, int(period * 1e9),
                            Clock(clock_type=ClockType.STEADY_TIME), context=node.context,
                            autostart=False)
        node.add_waitable(self)

    def resume(self) -> None:
        """Run, if paused; a running timer keeps its phase."""
        with self._lock:
            if not self._destroyed and self._timer.is_canceled():
                self._timer.reset()  # wakes a waiting executor: rcl triggers the timer's guard

    def pause(self) -> None:
        """Stop calling until the next :meth:`resume`; a firing not yet taken is dropped."""
        with self._lock:
            if not self._destroyed:
                self._timer.cancel()

    def set_period(self, period: float) -> None:
        """Call every ``period`` seconds from the next call on."""
        with self._lock:
            if not self._destroyed:
                self._timer.timer_period_ns = int(period * 1e9)

    def destroy(self) -> None:
        """Stop for good, and leave the node; the rcl timer goes once no wait set holds it."""
        with self._lock:
            if self._destroyed:
                return
            self._destroyed = True
            self._timer.cancel()
        self._node.remove_waitable(self)
        self._timer.destroy()

    # --- the Waitable API, called by the executor ------------------------------------------------

    def __enter__(self) -> None:
        self._timer.handle.__enter__()  # raises InvalidHandle once destroyed: the executor skips it

    def __exit__(self, *exc_info: Any) -> None:
        self._timer.handle.__exit__(*exc_info)

    def get_num_entities(self) -> NumberOfEntities:
        """One timer."""
        return NumberOfEntities(num_timers=1)

    def add_to_wait_set(self, wait_set: Any) -> None:
        """Add the rcl timer; a paused one never wakes the wait (rcl skips canceled timers)."""
        self._index = None
        if self._timer.handle.pointer:  # zero once destroyed (the executor failed to enter it)
            self._index = wait_set.add_timer(self._timer.handle)

    def is_ready(self, wait_set: Any) -> bool:
        """Whether the timer fired in this wait."""
        return self._index is not None and wait_set.is_ready('timer', self._index)

    def take_data(self) -> bool:
        """Take the firing, unless a pause came first: whether the callback is to run."""
        with self._lock:
            if self._destroyed or not self._timer.is_ready():
                return False
            self._timer.reset()  # as rcl_timer_call: the next firing is a period from now
            return True

    async def execute(self, taken_data: bool) -> None:
        """Run the callback if the firing was taken."""
        if taken_data:
            self._callback()
