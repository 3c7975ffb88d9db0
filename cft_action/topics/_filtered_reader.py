# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The content filter of one rcl subscription: the one place where the package changes a filter.

rmw_fastrtps destroys and recreates the DataReader when a subscription gets its first filter, and
again when the filter is set back to ``""`` (docs/INTERNALS.md, section 4). A recreation while an
executor waits on the subscription is a use-after-free, and one after samples were queued loses
them. Every filtered reader of the package therefore follows one rule, kept here:

- the first filter is set before any executor can see the subscription
  (:meth:`FilteredReader.install`);
- every later change is in place, from one non-empty expression to another
  (:meth:`FilteredReader.change`), and ``""`` is refused;
- a filter that cannot be kept is abandoned for an expression that every sample matches, again in
  place (:meth:`FilteredReader.abandon`); the owner then behaves as unfiltered rclpy, for good, and
  the reason is in its state.

Every expression passes :mod:`cft_action.topics.sql` before it reaches rcl: Fast DDS terminates the
process on a ``LIKE`` or ``MATCH`` pattern that its regex engine rejects. Setting and reading a
filter hold one process-wide lock, because rcl documents those functions as not thread-safe;
:func:`has_filter` takes none: ``rcl_subscription_is_cft_enabled`` reads one ``bool`` of the
subscription (``rmw_subscription_t.is_cft_enabled``), which only the rmw's set call, made under the
lock, writes.

The owners, :class:`cft_action.ActionClient`, :class:`cft_action.ParameterEventHandler` and
:func:`cft_action.create_filtered_subscription`, only decide which expression they want now.
"""

from __future__ import annotations

import os
import threading
from typing import Any, Callable, ContextManager, Iterable, NamedTuple, Optional, Sequence

import rclpy

from cft_action import _rcl
from cft_action.topics import sql
from cft_action._rclpy_compat import PromptLogger
from cft_action.errors import ContentFilterError, InvalidArgumentError
from cft_action.topics.filters import ContentFilterOptions, dds_literals, Literal

__all__ = ['FilteredReader', 'ReaderFilterState', 'get_filter', 'has_filter', 'set_filter']

_rcl_lock = threading.Lock()


def set_filter(subscription_ptr: int, topic: str, expression: str,
               expression_parameters: Sequence[Literal] = ()) -> ContentFilterOptions:
    """Set a filter on an rcl subscription and verify that the rmw applies it.

    :return: the filter as set, its parameters quoted as DDS literals.
    :raises ContentFilterError: naming the expression and the topic, with rcl's error string, if
        the expression is empty, a parameter cannot be quoted, :mod:`cft_action.topics.sql` rejects
        the expression, rcl fails, or the rmw does not apply it.
    """
    return apply_filter(subscription_ptr, topic, expression, expression_parameters)[0]


def apply_filter(subscription_ptr: int, topic: str, expression: str,
                 expression_parameters: Sequence[Literal] = (), *,
                 filter_class: Optional[str] = None,
                 sql_expression: bool = True) -> tuple[ContentFilterOptions, Optional[int]]:
    """:func:`set_filter`, optionally with one of the library's filter classes
    (:func:`_rcl.set_content_filter`). ``sql_expression=False``: the expression is one of
    ``_rcl.RATE_FILTER_CLASS``'s, which that class's own grammar checks, not DDS-SQL.

    :return: the filter as set, and the filter object it created in this process, if any.
    :raises ContentFilterError: naming the expression and the topic, with rcl's error string, if
        the expression is empty, a parameter cannot be quoted, :mod:`cft_action.topics.sql` rejects
        the expression, rcl fails, or the rmw does not apply it.
    """
    if not expression:
        raise ContentFilterError(
            f'refusing to set an empty filter expression on {topic}: rmw_fastrtps would destroy '
            'and recreate the DataReader, which is a use-after-free under a waiting executor. To '
            'receive nothing, set an expression that never matches '
            '(cft_action.topics.filters.never_match_on(field)); to receive everything, one that '
            'always does, or create an unfiltered subscription')
    try:
        parameters = dds_literals(expression_parameters)
    except (TypeError, ValueError) as e:
        raise ContentFilterError(
            f'content filter {expression!r} on {topic}: bad expression parameter: {e}') from e
    described = f'content filter {expression!r} with parameters {parameters} on {topic}'
    try:
        if sql_expression:
            sql.check_filter(expression, parameters)
    except sql.FilterError as e:
        raise ContentFilterError(f'{described} was rejected: {e.reason}') from e
    with _rcl_lock:
        try:
            created = _rcl.set_content_filter(subscription_ptr, expression, parameters,
                                              filter_class=filter_class)
        except ContentFilterError as e:
            # rcl's own error string when rcl refused it; else why the library did not call rcl
            # (e.g. a filter class that this Fast DDS cannot have), which has no rcl error string.
            if e.ret is not None:
                reason = f'was rejected: {e.rcl_error or e}'
            else:
                reason = f'was not set: {e}'
            raise ContentFilterError(f'{described} {reason}', function=e.function, ret=e.ret,
                                     rcl_error=e.rcl_error) from e
        if not _rcl.is_cft_enabled(subscription_ptr):
            raise ContentFilterError(f'{described} was accepted but is not applied by '
                                     f'{rclpy.get_rmw_implementation_identifier()}')
    return ContentFilterOptions(expression, parameters), created


def get_filter(subscription_ptr: int) -> ContentFilterOptions:
    """Return an rcl subscription's filter as the rmw reports it.

    :raises ContentFilterError: if the rmw has no content filtering, or rcl fails.
    """
    with _rcl_lock:
        expression, parameters = _rcl.get_content_filter(subscription_ptr)
    return ContentFilterOptions(expression, parameters)


def has_filter(subscription_ptr: int) -> bool:
    """Return whether the rmw applies a content filter to an rcl subscription."""
    return _rcl.is_cft_enabled(subscription_ptr)


class ReaderFilterState(NamedTuple):
    """What every filtered reader reports, whatever its owner.

    :ivar active: whether a filter narrows what the subscription receives.
    :ivar reason: why not; empty while it does.
    :ivar expression: the filter in force; empty when not active.
    :ivar expression_parameters: its parameters, as DDS literals; empty when not active.
    :ivar updates: filter changes after the first installation, abandonment included; each is an
        event at every matched writer.
    """

    active: bool
    reason: str
    expression: str
    expression_parameters: tuple[str, ...]
    updates: int

    def unfiltered(self, reason: str) -> ReaderFilterState:
        """The state as an owner reports it while the filter does not narrow, for ``reason``."""
        return self._replace(active=False, reason=reason, expression='', expression_parameters=())


#: Environment variable with which operators override the ``writer_filtering`` argument of
#: :class:`cft_action.ActionClient` and :class:`cft_action.ParameterEventHandler`.
WRITER_FILTERING_ENV = 'CFT_ACTION_WRITER_FILTERING'

#: Which writers may filter: ``'guarded'`` (the default), only those in a process run under
#: ``cft-action guard``, which know the library's filter classes; ``'any'``, every Fast DDS
#: writer, with a DDS-SQL filter, which costs an unguarded writer's process time and can crash it
#: (docs/SAFETY.md).
WRITER_FILTERING = ('guarded', 'any')


def filter_class_for(writer_filtering: str, guarded_class: str) -> Optional[str]:
    """The filter class for ``writer_filtering`` (or its environment variable, which wins).

    :param guarded_class: the library's class for ``'guarded'``; ``'any'`` gives None, DDS-SQL.
    :raises ValueError: if the value names no known choice, saying where it came from.
    """
    from_env = os.environ.get(WRITER_FILTERING_ENV)
    value = from_env or writer_filtering
    if value not in WRITER_FILTERING:
        source = f'environment variable {WRITER_FILTERING_ENV}' if from_env else 'writer_filtering'
        raise InvalidArgumentError(
            f'{source}={value!r}: expected one of {", ".join(WRITER_FILTERING)}')
    return guarded_class if value == 'guarded' else None


class FilteredReader:
    """The content filter of one subscription, from its installation to its end.

    It is *pending* until :meth:`install` or :meth:`adopt`, then *active*, with a filter that
    changes only in place, and *unfiltered* for good after :meth:`fall_back`, :meth:`abandon` or
    :meth:`detach`, with the reason. Its :attr:`lock` serializes every change; an owner holds it
    too while it decides which expression it wants, so that the decision and the change are one
    step.

    :param logger: the owner's logger, for the one warning when the filter is not used.
    :param unfiltered: what happens without the filter, for that warning, e.g.
        ``'feedback filter not used, all feedback is received as with rclpy'``.
    :param match_all: an expression that every sample of the topic matches.
    :param filter_class: filter with this one of the library's own filter classes
        (cft_action/native/_filter_class.h), which only guarded writers know, instead of DDS-SQL,
        which every Fast DDS writer evaluates; the expressions must then be in that class's grammar.
    """

    def __init__(self, logger: PromptLogger, *, unfiltered: str, match_all: str,
                 filter_class: Optional[str] = None) -> None:
        self.lock = threading.RLock()
        self.filter_class = filter_class
        # The class's filter object created in this process, and its verdicts once it is gone;
        # under their own lock, which is taken alone, so that the verdicts can be read from a
        # callback that must not wait for the reader's lock.
        self._verdicts_lock = threading.Lock()
        self._created: Optional[int] = None
        self._reader_verdicts = 0
        self._topic = ''
        self._logger = logger
        self._unfiltered = unfiltered
        self._match_all = match_all
        self._handle: Optional[ContextManager[Any]] = None
        self._pointer = 0
        self._filter: Optional[ContentFilterOptions] = None
        self._updates = 0
        self._reason = ''
        self._ended = False

    # --- the state machine ----------------------------------------------------------------------

    def install(self, handle: ContextManager[Any], subscription_ptr: int, topic: str,
                options: ContentFilterOptions) -> bool:
        """Set the first filter, before any executor can see the subscription.

        :param handle: what keeps ``subscription_ptr`` alive while it is held (an rclpy handle).
        :param subscription_ptr: the ``rcl_subscription_t *``.
        :param topic: the subscription's topic, for messages.
        :return: True if the filter is active; False if it fell back, logged, with the reason.
        """
        with self.lock:
            self._topic = topic
            try:
                with handle:
                    self._filter, created = apply_filter(
                        subscription_ptr, self._topic, *options, filter_class=self.filter_class)
                with self._verdicts_lock:
                    self._created = created
            except ContentFilterError as e:
                self.fall_back(f'installing the filter failed: {e}')
                return False
            self._handle, self._pointer = handle, subscription_ptr
            return True

    def adopt(self, handle: ContextManager[Any], subscription_ptr: int, topic: str,
              options: ContentFilterOptions, created: Optional[int] = None) -> None:
        """Take over a subscription that was created with ``options`` as its first filter.

        :param created: the filter object of :attr:`filter_class` that this process created for
            it, if any (:func:`cft_action.topics.subscription.subscribe_filtered`).
        """
        with self.lock:
            self._topic = topic
            self._handle, self._pointer, self._filter = handle, subscription_ptr, options
            with self._verdicts_lock:
                self._created = created

    def change(self, options: ContentFilterOptions) -> bool:
        """Change the filter in place, if it differs; the filter stays as it was on failure.

        :return: True if a change was made, False if ``options`` is the filter in force.
        :raises ContentFilterError: if the reader is not active, or the change is rejected.
        """
        with self.lock:
            if self._filter is None or self._handle is None:
                raise ContentFilterError(
                    f'the filter of {self._topic} cannot change: {self._reason or "not installed"}')
            if options == self._filter:
                return False
            with self._handle:
                self._filter = apply_filter(self._pointer, self._topic, *options,
                                            filter_class=self.filter_class)[0]
            self._updates += 1
            return True

    def update(self, options: ContentFilterOptions) -> bool:
        """Change the filter in place if it is active; abandon it if the change is rejected.

        :return: True if a change was made.
        """
        with self.lock:
            if self._filter is None:
                return False
            try:
                return self.change(options)
            except ContentFilterError as e:
                self.abandon(f'a filter update failed: {e}')
                return False

    def abandon(self, reason: str) -> None:
        """Let every sample through again, in place, and stay unfiltered for good."""
        with self.lock:
            if self._filter is not None and self._handle is not None:
                try:
                    with self._handle:
                        apply_filter(self._pointer, self._topic, self._match_all,
                                     filter_class=self.filter_class)
                    self._updates += 1
                except ContentFilterError as e:
                    reason += ('; and letting everything through failed too, samples may be '
                               f'lost: {e}')
            self.fall_back(reason)

    def fall_back(self, reason: str, *, log: bool = True) -> None:
        """Use no filter from now on, because of ``reason``; log it once unless ``log`` is False."""
        with self.lock:
            self._filter, self._reason = None, reason
            if log:
                self._logger.warning(f'{self._unfiltered}: {reason}')

    def detach(self, reason: str) -> None:
        """The subscription is being destroyed: no call reaches it from now on."""
        with self.lock:
            with self._verdicts_lock:
                if self._created is not None:
                    self._reader_verdicts = _rcl.filter_class_verdicts(self._created)
                self._created = None  # freed with the subscription's filtered topic
            self._filter, self._handle, self._reason, self._ended = None, None, reason, True

    # --- what it reports ------------------------------------------------------------------------

    @property
    def filter(self) -> Optional[ContentFilterOptions]:
        """The filter in force, or None when the reader is not (or no longer) filtered."""
        return self._filter

    @property
    def reader_verdicts(self) -> Optional[int]:
        """Samples that this process's filter judged itself, which the writer did not filter.

        None when unknown: not a filter class of the library's, or its filter was created by the
        preloaded guard.
        """
        with self._verdicts_lock:
            if self._created is None:
                return self._reader_verdicts if self._ended and self.filter_class else None
            return _rcl.filter_class_verdicts(self._created)

    def filtered_in(self, taken: int, writers: Callable[[], Iterable[Any]]) -> str:
        """Where the samples that the filter rejects are dropped, ``taken`` samples in.

        ``'writer'`` (by the writers), ``'reader'`` (by this reader: a writer does not know the
        filter's class), ``'none'`` (no filter) or ``'unknown'`` (nothing taken yet, or a writer
        this process may have discovered before it could tell).

        :param writers: The GIDs (``TopicEndpointInfo.endpoint_gid``) of the topic's publishers
            in other participants. A writer that filters for the library's classes says so in its
            discovery data (a guarded one), since its samples carry no filter signature for them
            (:func:`cft_action._rcl.writer_filters`); asked only for such a class.
        """
        if self._filter is None:  # one reference read: this does not take the reader's lock
            return 'none'
        if not self.filter_class:
            return 'writer'  # DDS-SQL: every Fast DDS writer filters (up to its reader limit)
        if not taken:
            return 'unknown'
        known = [_rcl.writer_filters(gid) for gid in writers()]
        if known and all(known):
            return 'writer'
        return 'reader' if False in known else 'unknown'

    @property
    def updates(self) -> int:
        """Filter changes since the first installation."""
        return self._updates

    @property
    def reason(self) -> str:
        """Why the reader is not filtered; empty while it is, or before its installation."""
        return self._reason

    @property
    def ended(self) -> bool:
        """Whether :meth:`detach` was called."""
        return self._ended

    @property
    def state(self) -> ReaderFilterState:
        """A snapshot of the common fields."""
        with self.lock:
            shown = self._filter
            return ReaderFilterState(
                active=shown is not None, reason=self._reason,
                expression=shown.filter_expression if shown is not None else '',
                expression_parameters=tuple(shown.expression_parameters) if shown else (),
                updates=self._updates)

    def read(self) -> ContentFilterOptions:
        """The filter as the middleware reports it; ``('', [])`` when it has none.

        After :meth:`abandon` that is the expression that matches everything.
        """
        with self.lock:
            if self._handle is None:
                return ContentFilterOptions('', [])
            with self._handle:
                if not has_filter(self._pointer):
                    return ContentFilterOptions('', [])
                return get_filter(self._pointer)
