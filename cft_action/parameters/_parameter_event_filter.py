# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The parameter event handler's filter: the nodes its callbacks watch, and the reader that sets it.

The handler's callbacks decide which expression is wanted (the watched nodes, every node while a
node-agnostic callback is registered, or the user's own), :class:`FilteredReader` sets it, and an
:class:`ArrivalGate` proves that the publishers of other processes apply it. See
:mod:`cft_action.parameters.parameter_events` for what is filtered where, and why.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from typing import Any, Callable, NamedTuple, Optional, Sequence

import rclpy
from rcl_interfaces.msg import ParameterEvent
from rcl_interfaces.srv import GetParameterTypes
from rclpy.node import Node
from rclpy.subscription import Subscription

from cft_action import _rcl
from cft_action.topics._filtered_reader import filter_class_for, FilteredReader
from cft_action.topics._program_mark import ProgramMark, REREAD_S
from cft_action._rclpy_compat import PromptLogger
from cft_action.topics.arrival import ArrivalGate, ProbeTarget, RemotePublishers
from cft_action.errors import ContentFilterError
from cft_action.topics.filters import (ContentFilterOptions, dds_literal, dds_literals, Literal,
                                never_match_on)
from cft_action.topics.subscription import subscribe_filtered

__all__ = ['ALL_NODES', 'NO_NODES', 'PARAMETER_EVENTS_TOPIC', 'ParameterEventFilter',
           'ParameterEventFilterState', 'node_filter']

PARAMETER_EVENTS_TOPIC = '/parameter_events'

#: The field of ``rcl_interfaces/msg/ParameterEvent`` that the filter tests.
NODE_FIELD = 'node'

#: An expression that every parameter event matches: "all nodes", reachable in place.
ALL_NODES = f'{NODE_FIELD} = {NODE_FIELD}'

#: An expression that no parameter event matches: "no node", used instead of ``""``, which would
#: make rmw_fastrtps recreate the DataReader.
NO_NODES = never_match_on(NODE_FIELD)

#: Fast DDS accepts at most ``%0`` .. ``%99``.
MAX_EXPRESSION_PARAMETERS = 100

_EVENT_CALLBACK_REASON = ('a parameter event callback (add_parameter_event_callback) is registered '
                          'and needs the events of every node')


class ParameterEventFilterState(NamedTuple):
    """A snapshot of a :class:`ParameterEventHandler`'s filter.

    :ivar mode: ``'nodes'`` (filtered on the watched nodes), ``'all'`` (a parameter event callback
        needs every event), ``'user'`` (an expression set by
        :meth:`ParameterEventHandler.set_parameter_event_filter`) or ``'off'`` (no content filter
        can be used; see ``reason``).
    :ivar active: whether the filter set on the subscription narrows what it receives.
    :ivar reason: why the filter is not active; empty when it is.
    :ivar expression: the filter expression set on the subscription; empty when not active. The
        publishers apply it once discovery has brought it to them: see ``confirmed``.
    :ivar expression_parameters: its parameters, as DDS literals; empty when not active.
    :ivar updates: filter changes sent after the subscription was created; each one reaches every
        ``/parameter_events`` writer in the domain.
    :ivar watched_nodes: fully qualified names of the nodes that parameter callbacks watch, sorted.
    :ivar events_received: parameter events taken by the subscription, whichever callbacks they
        reached.
    :ivar confirmed: whether the publishers are known to apply the filter set on the subscription.
        True for the filter the subscription was created with, which a publisher receives with the
        match itself. After a change it is False: the change travels by discovery and the
        middleware acknowledges nothing, so until it arrives a publisher still applies its previous
        filter, narrower or wider, and drops what that one rejects (in mode ``'all'`` too).
        :meth:`ParameterEventHandler.wait_for_filter` proves the arrival and sets it back to True.
    :ivar filtered_in: where the events of unwatched nodes are dropped: ``'writer'`` (the nodes'
        writers do not send them: nodes run under the guard, or ``writer_filtering='any'``),
        ``'reader'`` (they cross the network and this handler's DDS reader drops them before
        Python: nodes nobody put under the guard), ``'none'`` (not filtered) or ``'unknown'``
        (no event yet, or a node this process discovered before its first use of cft_action).
        With both kinds of node, ``'reader'``.
    """

    mode: str
    active: bool
    reason: str
    expression: str
    expression_parameters: tuple[str, ...]
    updates: int
    watched_nodes: tuple[str, ...]
    events_received: int
    confirmed: bool
    filtered_in: str = 'unknown'


def is_quotable(node_name: str) -> bool:
    """Whether a DDS literal can hold the name: no ROS node name has a quote."""
    try:
        dds_literal(node_name)
    except ValueError:
        return False
    return True


def node_filter(node_names: Sequence[str], *, parameters: bool = True) -> ContentFilterOptions:
    """Return the filter that matches the parameter events of exactly ``node_names``.

    The names are sorted, so that the same set always gives the same expression. Up to 100 names
    are passed as parameters, ``node = %0 OR node = %1 ...``, each quoted as a DDS literal; beyond
    Fast DDS's 100 parameters, or without ``parameters``, the quoted names are written into the
    expression itself, as the library's node filter class takes them. No names give
    :data:`NO_NODES`.

    :param node_names: Fully qualified node names, as in ``ParameterEvent.node``.
    :param parameters: Whether to pass the names as expression parameters.
    :raises ValueError: if a name contains a quote character, which no DDS literal can hold (and
        no ROS node name contains).
    """
    names = sorted(set(node_names))
    if not names:
        return ContentFilterOptions(NO_NODES, [])
    literals = dds_literals(names)
    if parameters and len(names) <= MAX_EXPRESSION_PARAMETERS:
        return ContentFilterOptions(
            ' OR '.join(f'{NODE_FIELD} = %{i}' for i in range(len(names))), literals)
    return ContentFilterOptions(' OR '.join(f'{NODE_FIELD} = {lit}' for lit in literals), [])


def parameter_services(publishers: RemotePublishers) -> dict[bytes, list[ProbeTarget]]:
    """Each other participant with a parameter event publisher, and its nodes' services.

    A participant whose nodes' names are not known yet maps to no service: it stays pending.
    """
    services: dict[bytes, list[ProbeTarget]] = {}
    for participant, infos in publishers.by_participant().items():
        candidates = services.setdefault(participant, [])
        for info in infos:
            if info.node_name.startswith('_NODE_') or info.node_namespace.startswith('_NODE_'):
                continue  # rmw's placeholder while the node's name is not yet discovered
            name = f"{info.node_namespace.rstrip('/')}/{info.node_name}/get_parameter_types"
            if all(target.service_name != name for target in candidates):
                candidates.append(ProbeTarget(GetParameterTypes, name,
                                              GetParameterTypes.Request()))
    return services


class ParameterEventFilter:
    """Which parameter events the handler's subscription lets through, and the proof of arrival.

    Its reader's lock guards every change. It is never taken while rclpy's callback registry's
    mutex is held, and :attr:`state` is a snapshot read without it (its ``filtered_in`` takes only
    the reader's verdict lock), so a callback that reads the state cannot deadlock against an add
    or remove in another thread.

    :param node: The handler's node.
    :param logger: The handler's logger.
    :param writer_filtering: ``'guarded'``: the library's node filter class, which only guarded
        nodes' writers evaluate; ``'any'``: DDS-SQL, which every node's writer evaluates. Its
        environment variable wins (:func:`cft_action.topics._filtered_reader.filter_class_for`).
    """

    def __init__(self, node: Node, logger: PromptLogger, writer_filtering: str = 'guarded') -> None:
        self.reader = FilteredReader(
            logger, match_all=ALL_NODES,
            filter_class=filter_class_for(writer_filtering, _rcl.NODE_FILTER_CLASS),
            unfiltered='parameter event filter not used, all parameter events are received as '
                       'with rclpy')
        self._logger = logger
        self._watched: Counter[str] = Counter()  # node name -> parameter callbacks watching it
        self._event_callbacks = 0
        self._user: Optional[ContentFilterOptions] = None
        publishers = RemotePublishers(node, PARAMETER_EVENTS_TOPIC,
                                      (PARAMETER_EVENTS_TOPIC, '/rosout'))
        self._publishers = publishers
        self._gate = ArrivalGate(node, lambda: parameter_services(publishers), self.reader.lock)
        self._received_lock = threading.Lock()  # the event path takes only this one
        self._received = 0
        # Where the node class cannot be the reader's filter (Fast DDS 3.3+): the reader's program
        # mark, which the watched nodes' guarded writers apply; the handler's callbacks still see
        # only their own nodes' events, as rclpy's do.
        self._mark: Optional[ProgramMark] = None
        self._state = ParameterEventFilterState('nodes', False, '', '', (), 0, (), 0, True)

    @property
    def state(self) -> ParameterEventFilterState:
        """The latest snapshot, with the events received so far."""
        with self._received_lock:
            received = self._received
        if self._mark is not None:
            where = 'writer' if self._mark.all_route(self._publishers.gids()) else 'none'
        else:
            where = self.reader.filtered_in(received, self._publishers.gids)
        return self._state._replace(events_received=received, filtered_in=where)

    def subscribe(self, node: Node, deliver: Callable[[ParameterEvent], None],
                  cft_supported: bool, **kwargs: Any) -> Subscription:
        """Create the subscription, filtered on "no node" from the start where the rmw can.

        :param deliver: Hands an event to the handler's callbacks; it is counted first.
        :param cft_supported: Whether the rmw implementation has content filters.
        :param kwargs: ``qos_profile``, ``callback_group``, ``event_callbacks``,
            ``qos_overriding_options`` and ``raw``, as for ``Node.create_subscription``.
        """
        qos_profile = kwargs.pop('qos_profile')

        def callback(event: ParameterEvent) -> None:
            with self._received_lock:
                self._received += 1
            deliver(event)

        with self.reader.lock:
            try:
                if not cft_supported:
                    self.reader.fall_back(
                        f'the rmw implementation {rclpy.get_rmw_implementation_identifier()} has '
                        'no content filter')
                else:
                    nothing = ContentFilterOptions(NO_NODES, [])
                    try:
                        subscription, created = subscribe_filtered(
                            node, ParameterEvent, PARAMETER_EVENTS_TOPIC, callback, qos_profile,
                            *nothing, filter_class=self.reader.filter_class, **kwargs)
                    except ContentFilterError as e:
                        self.reader.fall_back(f'installing the filter failed: {e}')
                    else:
                        with subscription.handle:
                            self.reader.adopt(subscription.handle, subscription.handle.pointer,
                                              PARAMETER_EVENTS_TOPIC, nothing, created)
                        return subscription
                subscription = node.create_subscription(ParameterEvent, PARAMETER_EVENTS_TOPIC,
                                                        callback, qos_profile, **kwargs)
                if self.reader.filter_class is not None:
                    self._mark_reader(subscription)
                return subscription
            finally:
                self._publish_state()

    def _mark_reader(self, subscription: Subscription) -> None:
        """Where the node class cannot be the reader's filter: mark the reader with the program
        (Fast DDS 3.3+), so that guarded nodes' writers send only the watched nodes' events."""
        self._mark, _ = ProgramMark.install(subscription, _rcl.NODE_FILTER_CLASS,
                                            self._wanted()[2].filter_expression)
        if self._mark is not None:
            self._logger.info(
                'the parameter event subscription asks nodes that run under cft-action guard '
                '(Fast DDS 3.3+) for the watched nodes\' events only; other nodes send every '
                'event, as to rclpy')

    # --- what the callbacks want ----------------------------------------------------------------

    def watch(self, node_name: str) -> None:
        """A parameter callback watches this node."""
        with self.reader.lock:
            if not is_quotable(node_name):
                # A quote cannot be in a DDS literal, nor in a ROS node name: no event can ever
                # come from this node, so leaving it out of the filter loses nothing.
                self._logger.warning(
                    f'parameter callback for node {node_name!r}: no ROS node has this name '
                    '(it contains a quote), so the callback will never be called')
            self._watched[node_name] += 1
            self._refresh()

    def unwatch(self, node_name: str) -> None:
        """A parameter callback of this node was removed."""
        with self.reader.lock:
            self._watched[node_name] -= 1
            if self._watched[node_name] <= 0:
                del self._watched[node_name]
            self._refresh()

    def count_event_callbacks(self, change: int) -> None:
        """A parameter event callback was added (+1) or removed (-1)."""
        with self.reader.lock:
            self._event_callbacks += change
            if change > 0 and self._event_callbacks == 1 and self.reader.filter is not None \
                    and self._user is None:
                self._logger.info(
                    'parameter event callback added: the parameter event handler now receives '
                    'the events of every node, until the last such callback is removed')
            self._refresh()

    def set_user(self, filter_expression: str, expression_parameters: Sequence[Literal]) -> None:
        """See :meth:`ParameterEventHandler.set_parameter_event_filter`."""
        with self.reader.lock:
            if self.reader.filter is None:
                raise ContentFilterError(
                    f'cannot set parameter event filter {filter_expression!r}: the handler has no '
                    f'content filter: {self.reader.reason}')
            if not filter_expression:
                self._user = None
                self._refresh()
                return
            try:
                options = ContentFilterOptions(filter_expression,
                                               dds_literals(expression_parameters))
            except (TypeError, ValueError) as e:
                raise ContentFilterError(
                    f'parameter event filter {filter_expression!r}: bad expression parameter: '
                    f'{e}') from e
            previous = self.reader.filter
            try:
                changed = self.reader.change(options)
            except ContentFilterError as e:
                # An in-place change that rmw_fastrtps rejects leaves the reader as it was.
                hint = ('' if self.reader.filter_class is None else
                        f" (the handler filters with the {self.reader.filter_class} class, which "
                        "takes only \"node = 'NAME' OR ...\"; for DDS-SQL, create it with "
                        "writer_filtering='any')")
                raise ContentFilterError(
                    f'parameter event filter {filter_expression!r} was rejected{hint}, the filter '
                    f'stays {previous.filter_expression!r}: {e}', function=e.function,
                    ret=e.ret, rcl_error=e.rcl_error) from e
            if changed:
                self._log_change(options)
            self._user = options
            self._publish_state()

    def configure_nodes(self, node_names: Optional[Sequence[str]]) -> bool:
        """See :meth:`ParameterEventHandler.configure_nodes_filter`."""
        try:
            if node_names:
                self.set_user(*self._node_filter(node_names))
            else:
                self.set_user('', ())
        except (ContentFilterError, ValueError) as e:
            self._logger.warning(f'configure_nodes_filter({node_names!r}) failed: {e}')
            return False
        return True

    def wait(self, timeout_sec: Optional[float]) -> bool:
        """See :meth:`ParameterEventHandler.wait_for_filter`."""
        with self.reader.lock:
            if self.reader.ended:
                return False
            target = self._version()
            if self._gate.is_confirmed(target):
                return True
        start = time.monotonic()
        if not self._gate.wait(target, timeout_sec):
            return False
        if self._mark is not None:  # the writers read an arrived mark at a write within REREAD_S
            if timeout_sec is not None and timeout_sec - (time.monotonic() - start) < REREAD_S:
                return False
            time.sleep(REREAD_S)
        with self.reader.lock:
            if self.reader.ended or self._version() != target:
                return False
            self._publish_state()
        return True

    def detach(self) -> None:
        """The handler is destroyed: no filter changes from now on."""
        with self.reader.lock:
            self.reader.detach('the handler was destroyed')
            self._publish_state()

    # --- the middleware's filter, and the state -------------------------------------------------

    def _wanted(self) -> tuple[str, str, ContentFilterOptions]:
        """Return ``(mode, reason, filter)`` for the callbacks registered now."""
        if self._user is not None:
            return 'user', '', self._user
        if self._event_callbacks:
            return 'all', _EVENT_CALLBACK_REASON, ContentFilterOptions(ALL_NODES, [])
        return 'nodes', '', self._node_filter([n for n in self._watched if is_quotable(n)])

    def _node_filter(self, node_names: Sequence[str]) -> ContentFilterOptions:
        # The library's class takes no parameters: its names are in the expression.
        return node_filter(node_names, parameters=self.reader.filter_class is None)

    def _version(self) -> int:
        """The filter's version that the writers are to apply: its changes, or its mark's."""
        return self.reader.updates + (self._mark.updates if self._mark is not None else 0)

    def _refresh(self) -> None:
        """Bring the middleware's filter in line with the callbacks, if it differs from them."""
        wanted = self._wanted()[2]
        if self.reader.filter is not None:
            # In place, from one non-empty expression to another: safe under a spinning executor.
            if self.reader.update(wanted):
                self._log_change(wanted)
        elif self._mark is not None:
            why = self._mark.change(wanted.filter_expression)
            if why and self._mark.change(ALL_NODES):
                self._logger.warning(f'the parameter event subscription\'s mark could not '
                                     f'change ({why}): guarded nodes may withhold watched events')
            elif why:
                self._logger.warning(f'the parameter event subscription\'s mark could not '
                                     f'change ({why}): it asks for every event now')
        self._publish_state()

    def _log_change(self, options: ContentFilterOptions) -> None:
        self._logger.debug(f'parameter event filter: {options.filter_expression!r} '
                           f'{options.expression_parameters} (update {self.reader.updates})')

    def _publish_state(self) -> None:
        common = self.reader.state
        if self.reader.filter is None and self._mark is not None:
            mode, reason = self._wanted()[0], common.reason  # the writers' mark, no reader filter
        elif self.reader.filter is None:
            mode, reason = 'off', common.reason
        else:
            mode, reason, _ = self._wanted()
        if mode in ('all', 'off'):  # the reader's filter lets everything through, or there is none
            common = common.unfiltered(reason)
        self._state = ParameterEventFilterState(
            mode, **common._asdict(), watched_nodes=tuple(sorted(self._watched)),
            events_received=0, confirmed=self._gate.is_confirmed(self._version()))
