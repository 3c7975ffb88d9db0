# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Rate-limited and polled subscriptions, decided at the publisher.

A subscription made by :func:`cft_action.create_filtered_subscription` with ``max_rate`` or
``poll`` is filtered with the library's class ``CFT_ACTION_RATE``
(``cft_action/native/_rate_program.h``), whose verdict is kept per publisher:

- ``max_rate=HZ``: at most one message per ``1/HZ`` seconds from each publisher; the one that
  passes is the first after the interval. :func:`set_max_rate` changes it, ``None`` lifts it.
- ``poll=N``: the next ``N`` messages of each publisher, then nothing; :func:`poll` asks for ``n``
  more, :func:`stop_polling` returns to every message (within ``max_rate``).

A publisher in a process run under ``cft-action guard`` decides when it writes a message, and does
not send the others (reliable readers get GAPs, so they never stall). Any other publisher sends
everything, and this process's DDS reader applies the same rule per publisher before Python. Where
the class cannot be used at all (another rmw, no C library), the subscription's callback applies
it in Python, to all publishers together; :func:`rate_filter_state` says which.

A change (a poll, a new rate) travels to the publishers by discovery, like every filter change:
until it has arrived, a publisher applies the previous filter.
"""

from __future__ import annotations

import inspect
import math
import threading
import time
import weakref
from typing import Any, Callable, NamedTuple, Optional

from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.subscription import Subscription

from cft_action import _rcl, guard
from cft_action.errors import ContentFilterError, InvalidArgumentError
from cft_action.topics._filtered_reader import apply_filter

__all__ = ['RateFilterState', 'active_subscription_count', 'poll', 'rate_filter_state',
           'set_max_rate', 'stop_polling']


class RateFilterState(NamedTuple):
    """A snapshot of a rate-limited or polled subscription.

    :ivar max_rate: the rate limit in Hz, or None.
    :ivar polling: whether only polled messages pass.
    :ivar polled: the messages polled so far, per publisher (the sum of every poll's ``n``).
    :ivar filtered_in: where messages beyond the rate or the polls are dropped: ``'writer'`` (by
        every publisher: all run under the guard), ``'reader'`` (this process's DDS reader drops
        those of at least one publisher that sent them), ``'python'`` (the class cannot be used:
        the callback drops them), or ``'unknown'`` (no publisher is matched yet).
    :ivar reason: why the middleware does not filter (``filtered_in == 'python'``), else ``''``.
    :ivar reader_verdicts: the verdicts this process's DDS reader gave, one per message that a
        publisher sent without deciding (0 while every publisher decides).
    :ivar layout_mismatches: messages that this process's rate filters passed unfiltered because
        the Fast DDS layout the library was built for is not the loaded one's (0, or say so).
    """

    max_rate: Optional[float]
    polling: bool
    polled: int
    filtered_in: str
    reason: str
    reader_verdicts: int = 0
    layout_mismatches: int = 0


#: The rate class's largest period (INT64_MAX ns): its grammar refuses a larger number.
MAX_PERIOD_NS = 2**63 - 1


def check_max_rate(max_rate: Optional[float], name: str = 'max_rate') -> Optional[float]:
    """``max_rate`` as a float, or None; ``name``: the argument's, for the error.

    :raises InvalidArgumentError: if it is not a positive, finite number.
    """
    if max_rate is None:
        return None
    if isinstance(max_rate, bool) or not isinstance(max_rate, (int, float)):
        raise InvalidArgumentError(f'{name}={max_rate!r}: expected a number of Hz, or None')
    if not math.isfinite(max_rate) or max_rate <= 0:
        raise InvalidArgumentError(f'{name}={max_rate!r}: expected a positive, finite rate in Hz')
    return float(max_rate)


def _check_count(name: str, n: Any) -> int:
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise InvalidArgumentError(f'{name}={n!r}: expected a whole number of messages, >= 0')
    return n


class RateFilter:
    """One subscription's rate limit and polls: the expression that says them, and, where the class
    cannot be used, the same rule applied in Python.

    :param max_rate: Hz, or None.
    :param poll: the messages polled at creation, or None for a subscription that does not poll.
    """

    def __init__(self, max_rate: Optional[float], poll: Optional[int]) -> None:
        self.max_rate = check_max_rate(max_rate)
        self.can_poll = poll is not None
        self.polling = poll is not None
        self.total = self.last = 0 if poll is None else _check_count('poll', poll)
        self.reason = ''  # why the class is not used: then the Python gate filters
        self.created: Optional[int] = None  # the class's filter in this process's reader
        self._lock = threading.Lock()
        self._next_pass = 0.0
        self._remaining = self.last

    def expression(self) -> str:
        """The filter in the class's grammar (``cft_action/native/_rate_program.h``)."""
        period = 0
        if self.max_rate is not None:  # periods past the grammar's INT64_MAX ns (292 years) are it
            ns = 1e9 / self.max_rate
            period = MAX_PERIOD_NS if ns >= MAX_PERIOD_NS else max(1, round(ns))
        polled = f' poll={self.total}/{self.last}' if self.polling else ''
        return f'period={period}{polled}'

    def poll(self, n: int) -> None:
        """Ask for ``n`` more messages of each publisher."""
        if not self.can_poll:
            raise InvalidArgumentError(
                'poll() on a subscription created without poll=: create it with '
                'create_filtered_subscription(..., poll=0) to poll it')
        n = _check_count('n', n)
        with self._lock:
            self.total += n
            self.last = n
            self._remaining = n if not self.polling else self._remaining + n
            self.polling = True

    def stop_polling(self) -> None:
        """Let every message through again (within ``max_rate``)."""
        with self._lock:
            self.polling = False

    def set_max_rate(self, max_rate: Optional[float]) -> None:
        """Change the rate limit; None lifts it."""
        checked = check_max_rate(max_rate)
        with self._lock:
            self.max_rate = checked

    def gate(self, callback: Callable[..., Any]) -> Callable[..., Any]:
        """``callback`` behind the same rule in Python, for a subscription the class cannot
        filter: it is applied to all publishers together, since rclpy's callbacks do not say
        which publisher a message came from. It takes the message info where ``callback`` takes
        it (rclpy's rule: a callback that cannot be called with the message alone)."""
        def passes() -> bool:
            with self._lock:
                now = time.monotonic()
                if self.polling and self._remaining == 0:
                    return False
                if self.max_rate is not None and now < self._next_pass:
                    return False
                self._next_pass = now + 1.0 / self.max_rate if self.max_rate else 0.0
                if self.polling:
                    self._remaining -= 1
            return True

        def with_info(message: Any, info: Any) -> Any:
            return callback(message, info) if passes() else None

        def message_only(message: Any) -> Any:
            return callback(message) if passes() else None

        try:
            inspect.signature(callback).bind(object())
        except TypeError:
            return with_info
        return message_only


#: The rate filters of the subscriptions made with ``max_rate`` or ``poll``.
_filters: weakref.WeakKeyDictionary[Subscription, RateFilter] = weakref.WeakKeyDictionary()


def register(subscription: Subscription, rate_filter: RateFilter) -> None:
    """Remember ``rate_filter`` as ``subscription``'s (by :func:`create_filtered_subscription`)."""
    _filters[subscription] = rate_filter


def _filter_of(subscription: Subscription) -> RateFilter:
    rate_filter = _filters.get(subscription)
    if rate_filter is None:
        raise InvalidArgumentError(
            f'{subscription.topic_name}: the subscription was not created with max_rate or poll '
            '(create_filtered_subscription(..., max_rate=HZ) or poll=N)')
    return rate_filter


def _apply(subscription: Subscription, rate_filter: RateFilter) -> None:
    if rate_filter.reason:
        return  # filtered in Python: the gate reads the filter's fields
    with subscription.handle:
        apply_filter(subscription.handle.pointer, subscription.topic_name,
                     rate_filter.expression(), sql_expression=False)


def _change(subscription: Subscription, change: Callable[[RateFilter], None]) -> None:
    """Apply ``change`` to the subscription's filter, and the result to its reader; on an error
    from rcl, the filter is left as it was and the error raised."""
    rate_filter = _filter_of(subscription)
    before = (rate_filter.max_rate, rate_filter.polling, rate_filter.total, rate_filter.last)
    change(rate_filter)
    try:
        _apply(subscription, rate_filter)
    except ContentFilterError:
        (rate_filter.max_rate, rate_filter.polling, rate_filter.total,
         rate_filter.last) = before
        raise


def poll(subscription: Subscription, n: int) -> None:
    """Receive the next ``n`` messages of each publisher (after those polled before).

    :param subscription: a subscription created with ``poll=``.
    :param n: messages per publisher, ``>= 0``.
    :raises InvalidArgumentError: if ``n`` is not a whole number ``>= 0``, or the subscription
        was not created with ``poll=``.
    :raises ContentFilterError: if rcl rejects the change (the subscription keeps its filter).
    """
    _change(subscription, lambda f: f.poll(n))


def stop_polling(subscription: Subscription) -> None:
    """Receive every message again (within the subscription's ``max_rate``), until the next poll.

    :raises InvalidArgumentError: if the subscription was not created with ``poll=``.
    """
    if not _filter_of(subscription).can_poll:
        raise InvalidArgumentError(f'{subscription.topic_name}: stop_polling() on a subscription '
                                   'created without poll=')
    _change(subscription, RateFilter.stop_polling)


def set_max_rate(subscription: Subscription, max_rate: Optional[float]) -> None:
    """Change the subscription's rate limit to ``max_rate`` Hz per publisher; None lifts it.

    :raises InvalidArgumentError: if ``max_rate`` is not positive and finite, or the subscription
        was not created with ``max_rate`` or ``poll``.
    """
    _change(subscription, lambda f: f.set_max_rate(max_rate))


def rate_filter_state(subscription: Subscription, node: Node) -> RateFilterState:
    """The subscription's rate limit and polls, and where they are applied.

    :param node: the subscription's node, whose graph tells which publishers filter.
    """
    rate_filter = _filter_of(subscription)
    if rate_filter.reason:
        where = 'python'
    else:
        known = [_rcl.writer_filters(bytes(info.endpoint_gid))
                 for info in node.get_publishers_info_by_topic(subscription.topic_name)]
        where = 'writer' if known and all(known) else 'reader' if False in known else 'unknown'
    verdicts = 0 if rate_filter.created is None else _rcl.filter_class_verdicts(
        rate_filter.created)
    return RateFilterState(rate_filter.max_rate, rate_filter.polling, rate_filter.total, where,
                           rate_filter.reason, verdicts, _rcl.rate_layout_mismatches())


def active_subscription_count(publisher: Publisher) -> int:
    """How many matched subscriptions would take a message published now.

    In a process under the guard (``cft-action guard -- ...``; :func:`cft_action.guard.is_active`
    tells), the matched subscriptions less those whose rate window is closed or whose polls have
    no message left: exact for this library's rate limits and polls. A subscription with a DDS-SQL
    filter is counted (whether it takes a message depends on the message). Elsewhere the writer
    cannot be asked, and this is the matched count (``publisher.get_subscription_count()``), an
    upper bound. A count of 0 is exact in both: nothing would take the message, and the work of
    making it can be skipped.
    """
    matched = publisher.get_subscription_count()
    closed = guard.closed_readers(_rcl.publisher_gid(publisher.handle.pointer))
    return matched if closed is None else max(0, matched - closed)
