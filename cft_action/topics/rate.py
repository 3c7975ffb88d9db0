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
from cft_action.topics._program_mark import ProgramMark, REREAD_S

__all__ = ['RateFilterState', 'active_subscription_count', 'poll', 'rate_filter_state',
           'set_max_rate', 'stop_polling']


class RateFilterState(NamedTuple):
    """A snapshot of a rate-limited or polled subscription.

    :ivar max_rate: the rate limit in Hz, or None.
    :ivar polling: whether only polled messages pass.
    :ivar polled: the messages polled so far, per publisher (the sum of every poll's ``n``).
    :ivar filtered_in: where messages beyond the rate or the polls are dropped: ``'writer'`` (by
        every publisher: all run under the guard), ``'reader'`` (this process's DDS reader drops
        those of at least one publisher that sent them), ``'python'`` (the callback drops those of
        at least one publisher: the class cannot be used), or ``'unknown'`` (no publisher is
        matched yet).
    :ivar reason: why this process's DDS reader cannot filter (the class cannot be used: the
        callback then applies the rule, and on Fast DDS 3.3+ guarded publishers apply it too),
        else ``''``.
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


class _Publisher:
    """One publisher's side of a rate filter applied in this process (``_rate_program.c``'s)."""

    __slots__ = ('passed_at', 'remaining')

    def __init__(self, remaining: int) -> None:
        self.passed_at: Optional[int] = None  # ns of the last message that passed
        self.remaining = remaining  # polled messages still to pass


class RateFilter:
    """One subscription's rate limit and polls: the expression that says them, and, where the class
    cannot be used, the same rule applied in this process, per publisher.

    :param max_rate: Hz, or None.
    :param poll: the messages polled at creation, or None for a subscription that does not poll.
    """

    def __init__(self, max_rate: Optional[float], poll: Optional[int]) -> None:
        self.max_rate = check_max_rate(max_rate)
        self.can_poll = poll is not None
        self.polling = poll is not None
        self.total = self.last = 0 if poll is None else _check_count('poll', poll)
        self.reason = ''  # why the class is not used: then the gate filters
        self.created: Optional[int] = None  # the class's filter in this process's reader
        # Where the class is not used, on Fast DDS 3.3+: the reader's program mark, which guarded
        # publishers apply (set by the subscription).
        self.mark: Optional[ProgramMark] = None
        self._lock = threading.Lock()
        self._publishers: dict[Optional[bytes], _Publisher] = {}
        self._routed: dict[bytes, tuple[bool, float]] = {}  # GID: (applies the mark, when seen)

    def period_ns(self) -> int:
        """The rate limit's period in ns (0: none); past the grammar's INT64_MAX (292 years) it."""
        if self.max_rate is None:
            return 0
        ns = 1e9 / self.max_rate
        return MAX_PERIOD_NS if ns >= MAX_PERIOD_NS else max(1, round(ns))

    def expression(self) -> str:
        """The filter in the class's grammar (``cft_action/native/_rate_program.h``)."""
        polled = f' poll={self.total}/{self.last}' if self.polling else ''
        return f'period={self.period_ns()}{polled}'

    def writer_expression(self) -> str:
        """The program that this reader's mark asks guarded Fast DDS 3.3+ writers to apply: the
        filter, with each poll's last count raised to the total, so that a writer that learns of
        the reader late never passes fewer messages than this process's gate takes."""
        polled = f' poll={self.total}/{self.total}' if self.polling else ''
        return f'period={self.period_ns()}{polled}'

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
            for publisher in self._publishers.values():
                publisher.remaining = publisher.remaining + n if self.polling else n
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

    def _applies_mark(self, gid: Optional[bytes]) -> bool:
        """Whether publisher ``gid``'s writer applies this reader's mark (known to stay so)."""
        if gid is None or self.mark is None:
            return False
        known = self._routed.get(gid)
        now = time.monotonic()
        # a publisher that does not apply the mark may do so once its writer has read it
        if known is None or (not known[0] and now - known[1] >= REREAD_S):
            known = (bool(self.mark.routes(gid)), now)
            self._routed[gid] = known
        return known[0]

    def passes(self, info: Any) -> bool:
        """The verdict on a message with rclpy's message ``info`` (None: not known): per
        publisher where ``info`` names it, else for all publishers together.

        A publisher that applies the reader's mark sent only what its program passed, on its own
        clock: its messages are held to half the period, so that a message it passed is never
        dropped for arriving early, while one it sent before it knew the mark still counts."""
        gid, at = None, 0
        if isinstance(info, dict):
            publisher = info.get('publisher_gid')
            if isinstance(publisher, dict) and publisher.get('data') is not None:
                gid = bytes(publisher['data'])[:16]
            at = info.get('source_timestamp') or 0
        at = at or time.monotonic_ns()
        slack = self._applies_mark(gid)
        with self._lock:
            publisher = self._publishers.get(gid)
            if publisher is None:
                publisher = self._publishers[gid] = _Publisher(self.last)
            if self.polling and publisher.remaining == 0:
                return False
            period = self.period_ns()
            if period and publisher.passed_at is not None:
                if at < publisher.passed_at + (period - period // 2 if slack else period):
                    return False
            publisher.passed_at = at
            if self.polling:
                publisher.remaining -= 1
        return True

    def gate(self, callback: Callable[..., Any]) -> Callable[..., Any]:
        """``callback`` behind the same rule, for a subscription the class cannot filter. It takes
        rclpy's message info, to tell publishers apart (rclpy 7.1 and later say which publisher
        sent a message; before, all publishers are taken together), and passes it on where
        ``callback`` takes it (rclpy's rule: a callback that cannot be called with the message
        alone)."""
        try:
            inspect.signature(callback).bind(object())
            with_info = False
        except TypeError:
            with_info = True

        def gated(message: Any, info: Any) -> Any:
            if not self.passes(info):
                return None
            return callback(message, info) if with_info else callback(message)

        return gated


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
    if rate_filter.reason:  # filtered in this process: the gate reads the filter's fields
        if rate_filter.mark is not None:
            why = rate_filter.mark.change(rate_filter.writer_expression())
            if why:
                raise ContentFilterError(f'{subscription.topic_name}: the reader\'s program mark '
                                         f'was not changed: {why}')
        return
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
    gids = [bytes(info.endpoint_gid)
            for info in node.get_publishers_info_by_topic(subscription.topic_name)]
    if rate_filter.reason:
        mark = rate_filter.mark
        where = 'writer' if mark is not None and mark.all_route(gids) else 'python'
    else:
        known = [_rcl.writer_filters(gid) for gid in gids]
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
