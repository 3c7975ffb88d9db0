# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""A drop-in :class:`rclpy.parameter_event_handler.ParameterEventHandler` filtered by node.

Every node publishes its parameter changes on the one ``/parameter_events`` topic, and rclpy's
handler subscribes to all of it: it receives and deserializes the whole system's parameter traffic
to find the few events its callbacks ask for. This handler content-filters its subscription on the
event's ``node`` field (``node = %0 OR node = %1 ...``), so that the publishers' DataWriters send it
only the events of the nodes that its parameter callbacks watch.

What the middleware filters, and what stays in Python:

- **By node, in the middleware.** The filter covers exactly the nodes of the registered parameter
  callbacks, and changes only when that set of nodes changes.
- **By parameter name, in Python, as in rclpy.** DDS SQL has no "any element of" operator: Fast DDS
  accepts ``changed_parameters[0].name = %0``, but that tests one fixed position of the sequence,
  and an event carries any number of parameters, in the order of the set request, split between
  ``new_parameters`` and ``changed_parameters``. A name filter would have to OR every position up to
  an arbitrary bound and would still miss the parameters beyond it, so the handler filters names
  client-side, exactly as rclpy does.
- **Node-agnostic callbacks see everything.** While a callback added with
  :meth:`ParameterEventHandler.add_parameter_event_callback` is registered, every event must
  arrive, so the handler lets all of them through and says so in
  :attr:`ParameterEventHandler.parameter_event_filter_state`.

How the filter is changed safely. rmw_fastrtps destroys and recreates the DataReader when a reader
gets its first filter, and again when the filter is set back to ``""``; doing either while an
executor waits on the subscription is a use-after-free. So the subscription is created with a
filter before any executor can see it, and every later change is an in-place change from one
non-empty expression to another: "no node" is an expression that never matches, and "every node"
is ``node = node``, which always does.

When a change is in force. A change reaches each publisher by discovery, some milliseconds later,
and until then that publisher applies its previous filter; the middleware acknowledges nothing.
:attr:`ParameterEventHandler.parameter_event_filter_state` therefore reports a change as not
``confirmed`` until :meth:`ParameterEventHandler.wait_for_filter` has proven, by a round trip to
each publishing participant that discovery orders after the change, that it has arrived.

The node's time source does not depend on this subscription: rclpy's
:class:`rclpy.time_source.TimeSource` follows ``use_sim_time`` through
``Node.add_on_set_parameters_callback``, not through ``/parameter_events``, so no filter set here
can hide a ``use_sim_time`` change from the node's clock.

The hazard. Each filter change, and the creation and destruction of the filtered reader, is an
event at every ``/parameter_events`` writer in the domain, that is, at every node with parameter
events enabled, not only at the watched ones. With Fast DDS 2.14 such an event can crash a process
that publishes at that moment (eProsima/Fast-DDS#4878, docs/INTERNALS.md section 10). Measured with
``demos/parameter_events.py --soak``: 20 nodes in one process, each changing a parameter at 10 Hz,
crashed within 2, 10 and 102 updates (one every 50 ms); under :mod:`cft_action.guard` they survived
500. This handler therefore changes its filter only when the set of watched nodes changes; where
nodes publish parameter events often, run them under the guard.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from typing import Callable, NamedTuple, Optional, Sequence, Union

import rclpy
from rcl_interfaces.msg import ParameterEvent
from rcl_interfaces.srv import GetParameterTypes
from rclpy.callback_groups import CallbackGroup
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_event_handler import (
    ParameterCallbackHandle,
    ParameterEventCallbackHandle,
    ParameterEventHandler as _RclpyParameterEventHandler,
)
from rclpy.qos import qos_profile_parameter_events, QoSProfile
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.subscription import Subscription

from cft_action._filtered_reader import FilteredReader
from cft_action._rclpy_compat import PromptLogger, set_parameter_event_callbacks
from cft_action.arrival import node_participant, participant_of, ServiceProbe
from cft_action.errors import ContentFilterError
from cft_action.filters import dds_literal, dds_literals, Literal, never_match_on
from cft_action.subscription import (
    ContentFilterOptions,
    create_filtered_subscription,
    is_content_filter_supported,
)

__all__ = [
    'ALL_NODES', 'NO_NODES', 'ParameterEventFilterState', 'ParameterEventHandler',
    'node_filter', 'PARAMETER_EVENTS_TOPIC',
]

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

#: How often wait_for_filter polls its probes.
_PROBE_POLL_S = 0.01
#: How long wait_for_filter probes one node of a participant before it tries the next one.
_PROBE_TURN_S = 2.0

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


def _is_quotable(node_name: str) -> bool:
    try:
        dds_literal(node_name)
    except ValueError:
        return False
    return True


def node_filter(node_names: Sequence[str]) -> ContentFilterOptions:
    """Return the filter that matches the parameter events of exactly ``node_names``.

    The names are sorted, so that the same set always gives the same expression. Up to 100 names
    are passed as parameters, ``node = %0 OR node = %1 ...``, each quoted as a DDS literal; beyond
    Fast DDS's 100 parameters, the quoted names are written into the expression itself. No names
    give :data:`NO_NODES`.

    :param node_names: Fully qualified node names, as in ``ParameterEvent.node``.
    :raises ValueError: if a name contains a quote character, which no DDS literal can hold (and
        no ROS node name contains).
    """
    names = sorted(set(node_names))
    if not names:
        return ContentFilterOptions(NO_NODES, [])
    literals = dds_literals(names)
    if len(names) <= MAX_EXPRESSION_PARAMETERS:
        return ContentFilterOptions(
            ' OR '.join(f'{NODE_FIELD} = %{i}' for i in range(len(names))), literals)
    return ContentFilterOptions(' OR '.join(f'{NODE_FIELD} = {lit}' for lit in literals), [])


class ParameterEventHandler(_RclpyParameterEventHandler):
    """A ParameterEventHandler whose subscription receives only the nodes it watches.

    It takes the same arguments and has the same methods as
    :class:`rclpy.parameter_event_handler.ParameterEventHandler`, and runs the same callbacks in the
    same order; it only receives fewer events. The middleware filters by node; parameter names are
    still filtered in Python, because DDS SQL cannot test "any element" of the event's parameter
    sequences (see the module documentation).
    """

    def __init__(
        self,
        node: Node,
        qos_profile: Union[QoSProfile, int] = qos_profile_parameter_events,
        callback_group: Optional[CallbackGroup] = None,
        event_callbacks: Optional[SubscriptionEventCallbacks] = None,
        qos_overriding_options: Optional[QoSOverridingOptions] = None,
        raw: bool = False,
    ) -> None:
        """
        Create ParameterEventHandler.

        Usage example:

        .. code-block:: python
            import rclpy
            from cft_action import ParameterEventHandler

            handler = ParameterEventHandler(node)

            # Add parameter callback: the subscription now receives the events of /example only
            handle = handler.add_parameter_callback(
                parameter_name="example_parameter",
                node_name="example",
                callback=example_callable,
            )

            # Remove parameter callback: the subscription receives nothing
            handler.remove_parameter_callback(handle)

            # Add parameter event callback: the subscription receives every event
            handle = handler.add_parameter_event_callback(
                callback=example_callable,
            )

            # Remove parameter event callback
            handler.remove_parameter_event_callback(handle)
        ..

        The subscription is created with a filter that matches nothing, because no callback is
        registered yet, and grows as parameter callbacks are added. Where no content filter can be
        used (another rmw implementation, or the filter is rejected), the handler subscribes
        unfiltered, as rclpy's does, logs why once, and reports it in
        :attr:`parameter_event_filter_state`.

        :param node: Used to subscribe to parameter_events topic
        :param qos_profile: A QoSProfile or a history depth to apply to the subscription.
            In the case that a history depth is provided, the QoS history is set to
            KEEP_LAST, the QoS history depth is set to the value
            of the parameter, and all other QoS settings are set to their default values.
        :param callback_group: The callback group for the subscription. If ``None``, then the
            default callback group for the node is used.
        :param event_callbacks: User-defined callbacks for middleware events. Fast DDS counts the
            events that the publishers filtered out as *lost*, so a ``message_lost`` callback
            reports them too.
        :param qos_overriding_options: Options to customize QoS parameter overrides.
        :param raw: If ``True``, then received messages will be stored in raw binary
            representation.
        """
        # rclpy's constructor would create an unfiltered subscription, and giving that a first
        # filter later recreates its DataReader; so its three attributes are set here instead.
        self.node = node
        self.qos_profile = qos_profile  # type: ignore[assignment]  # rclpy types it QoSProfile only
        self._rclpy_callbacks = set_parameter_event_callbacks(self)  # what its methods use

        self._cft_logger = PromptLogger(node.get_logger().get_child('cft_action'))
        # The reader's lock guards the filter bookkeeping and the rmw calls. It is never taken
        # while the Callbacks mutex is held, and the event path takes only _received_lock, so a
        # callback that reads the state cannot deadlock against an add or remove in another thread.
        self._reader = FilteredReader(
            self._cft_logger, match_all=ALL_NODES,
            unfiltered='parameter event filter not used, all parameter events are received as '
                       'with rclpy')
        self._received_lock = threading.Lock()
        self._received = 0
        self._watched: Counter[str] = Counter()  # node name -> parameter callbacks watching it
        self._event_callback_count = 0
        self._user_filter: Optional[ContentFilterOptions] = None
        self._confirmed_updates = 0  # the reader's updates when wait_for_filter last proved them
        self._state = ParameterEventFilterState('nodes', False, '', '', (), 0, (), 0, True)

        self.parameter_event_subscription = self._subscribe(
            callback_group, event_callbacks, qos_overriding_options, raw)
        with self._reader.lock:
            self._publish_state()

    # --- subscription and filter ----------------------------------------------------------------

    def _subscribe(self, callback_group: Optional[CallbackGroup],
                   event_callbacks: Optional[SubscriptionEventCallbacks],
                   qos_overriding_options: Optional[QoSOverridingOptions],
                   raw: bool) -> Subscription:
        if not is_content_filter_supported(self.node):
            self._reader.fall_back(
                f'the rmw implementation {rclpy.get_rmw_implementation_identifier()} has no '
                'content filter')
        else:
            try:
                subscription = create_filtered_subscription(
                    self.node, ParameterEvent, PARAMETER_EVENTS_TOPIC, self._on_event,
                    self.qos_profile, NO_NODES, callback_group=callback_group,
                    event_callbacks=event_callbacks,
                    qos_overriding_options=qos_overriding_options, raw=raw)
            except ContentFilterError as e:
                self._reader.fall_back(f'installing the filter failed: {e}')
            else:
                with subscription.handle:
                    self._reader.adopt(subscription.handle, subscription.handle.pointer,
                                       PARAMETER_EVENTS_TOPIC, ContentFilterOptions(NO_NODES, []))
                return subscription
        return self.node.create_subscription(
            ParameterEvent, PARAMETER_EVENTS_TOPIC, self._on_event, self.qos_profile,
            callback_group=callback_group, event_callbacks=event_callbacks,
            qos_overriding_options=qos_overriding_options, raw=raw)

    def _on_event(self, event: ParameterEvent) -> None:
        with self._received_lock:
            self._received += 1
        self._rclpy_callbacks.event_callback(event)

    def _wanted(self) -> tuple[str, str, ContentFilterOptions]:
        """Return ``(mode, reason, filter)`` for the callbacks registered now."""
        if self._user_filter is not None:
            return 'user', '', self._user_filter
        if self._event_callback_count:
            return 'all', _EVENT_CALLBACK_REASON, ContentFilterOptions(ALL_NODES, [])
        return 'nodes', '', node_filter([n for n in self._watched if _is_quotable(n)])

    def _refresh(self) -> None:
        """Bring the middleware's filter in line with the callbacks, if it differs from them."""
        with self._reader.lock:
            if self._reader.filter is not None:
                _, _, wanted = self._wanted()
                try:
                    self._change(wanted)
                except ContentFilterError as e:
                    self._reader.abandon(f'a filter update failed: {e}')
            self._publish_state()

    def _change(self, options: ContentFilterOptions) -> None:
        # In place, from one non-empty expression to another: safe under a spinning executor.
        if self._reader.change(options):
            self._cft_logger.debug(
                f'parameter event filter: {options.filter_expression!r} '
                f'{options.expression_parameters} (update {self._reader.updates})')

    def _publish_state(self) -> None:
        common = self._reader.state
        if self._reader.filter is None:
            mode, reason = 'off', common.reason
        else:
            mode, reason, _ = self._wanted()
        shown = mode not in ('all', 'off')
        self._state = ParameterEventFilterState(
            mode=mode, active=shown, reason=reason,
            expression=common.expression if shown else '',
            expression_parameters=common.expression_parameters if shown else (),
            updates=common.updates, watched_nodes=tuple(sorted(self._watched)), events_received=0,
            confirmed=self._confirmed_updates == common.updates)

    # --- the rclpy API ----------------------------------------------------------------------------

    def add_parameter_callback(
        self,
        parameter_name: str,
        node_name: str,
        callback: Callable[[Parameter], None],
    ) -> ParameterCallbackHandle:
        """
        Add new parameter callback.

        Callbacks are called in FILO manner.

        If no other callback watches the node, the filter grows to include it after the callback is
        registered. The change reaches the publishers by discovery; until it arrives there, they
        still apply the previous filter, so an event of that node published in the meantime can be
        missed. :meth:`wait_for_filter` returns once it has arrived.

        :param parameter_name: Name of a parameter to tie callback to
        :param node_name: Name of a node, that the parameter should be related to
        :param callback: A callable to be called when the parameter is modified

        :return ParameterCallbackHandle: A handle that should be saved by the user
            so that the event_callback can be later removed.
        """
        handle = super().add_parameter_callback(parameter_name, node_name, callback)
        with self._reader.lock:
            if not _is_quotable(handle.node_name):
                # A quote cannot be in a DDS literal, nor in a ROS node name: no event can ever
                # come from this node, so leaving it out of the filter loses nothing.
                self._cft_logger.warning(
                    f'parameter callback for node {handle.node_name!r}: no ROS node has this name '
                    '(it contains a quote), so the callback will never be called')
            self._watched[handle.node_name] += 1
            self._refresh()
        return handle

    def remove_parameter_callback(
        self,
        handle: ParameterCallbackHandle,
    ) -> None:
        """
        Remove a ParameterCallbackHandle.

        Perform no callbacks on this parameter events in the future. If no other callback watches
        the node, the filter shrinks to leave it out.

        :param handle: ParameterCallbackHandle of a callback to be removed
        """
        super().remove_parameter_callback(handle)  # raises, as rclpy, for an unknown handle
        with self._reader.lock:
            self._watched[handle.node_name] -= 1
            if self._watched[handle.node_name] <= 0:
                del self._watched[handle.node_name]
            self._refresh()

    def add_parameter_event_callback(
        self,
        callback: Callable[[ParameterEvent], None],
    ) -> ParameterEventCallbackHandle:
        """
        Add new parameter event callback.

        Callbacks are called in FILO manner.

        Such a callback is not tied to a node, so while one is registered the handler lets the
        events of every node through, as rclpy's does; :attr:`parameter_event_filter_state` then
        has mode ``'all'``. A filter set with :meth:`set_parameter_event_filter` stays in force.
        The change reaches the publishers by discovery: an event that the previous filter rejects
        and that is published before the change arrives is missed. :meth:`wait_for_filter`
        returns once it has arrived.

        :param callback: A callable to be referenced on a ParameterEvent

        :return ParameterEventCallbackHandle: A handle that should be saved by the user
            so that the event_callback can be later removed.
        """
        handle = super().add_parameter_event_callback(callback)
        with self._reader.lock:
            self._event_callback_count += 1
            if self._event_callback_count == 1 and self._reader.filter is not None \
                    and self._user_filter is None:
                self._cft_logger.info(
                    'parameter event callback added: the parameter event handler now receives '
                    'the events of every node, until the last such callback is removed')
            self._refresh()
        return handle

    def remove_parameter_event_callback(
        self,
        handle: ParameterEventCallbackHandle,
    ) -> None:
        """
        Remove a ParameterEventCallbackHandle.

        Perform no callbacks on parameter events in the future. When the last one is removed, the
        filter narrows to the nodes of the parameter callbacks again.

        :param handle: ParameterEventCallbackHandle of a callback to be removed
        """
        super().remove_parameter_event_callback(handle)
        with self._reader.lock:
            self._event_callback_count -= 1
            self._refresh()

    def destroy(self) -> None:
        """Destroy the subscription to ``/parameter_events``."""
        with self._reader.lock:
            self._reader.detach('the handler was destroyed')  # no filter changes from now on
            self._publish_state()
        super().destroy()

    # --- filter API -------------------------------------------------------------------------------

    @property
    def parameter_event_filter_state(self) -> ParameterEventFilterState:
        """The filter's mode, whether it is active and why not, and its counters (read-only)."""
        with self._received_lock:
            received = self._received
        return self._state._replace(events_received=received)

    def set_parameter_event_filter(self, filter_expression: str,
                                   expression_parameters: Sequence[Literal] = ()) -> None:
        """
        Set an expression of one's own on the ``/parameter_events`` subscription.

        For example ``"(node = %0 AND stamp.sec > %1) OR node = %2"``. The expression replaces
        the automatic, per-node filter, and stays in force until it is cleared: callbacks added
        meanwhile receive only the events that it lets through.

        :param filter_expression: A DDS-SQL expression over the fields of
            ``rcl_interfaces/msg/ParameterEvent``; ``""`` clears it, and the handler filters on the
            watched nodes again (the subscription itself is never set to ``""``).
        :param expression_parameters: Values for ``%0`` .. ``%99``. Bare strings are quoted:
            ``/robot/arm`` is sent as ``'/robot/arm'``.
        :raises ContentFilterError: if the handler has no content filter (see
            :attr:`parameter_event_filter_state`), or if the expression or a parameter is
            rejected. The message names the expression; the previous filter stays in force.
        """
        with self._reader.lock:
            if self._reader.filter is None:
                raise ContentFilterError(
                    f'cannot set parameter event filter {filter_expression!r}: the handler has no '
                    f'content filter: {self._reader.reason}')
            if not filter_expression:
                self._user_filter = None
                self._refresh()
                return
            try:
                options = ContentFilterOptions(filter_expression,
                                               dds_literals(expression_parameters))
            except (TypeError, ValueError) as e:
                raise ContentFilterError(
                    f'parameter event filter {filter_expression!r}: bad expression parameter: '
                    f'{e}') from e
            previous = self._reader.filter
            try:
                self._change(options)
            except ContentFilterError as e:
                # An in-place change that rmw_fastrtps rejects leaves the reader as it was.
                raise ContentFilterError(
                    f'parameter event filter {filter_expression!r} was rejected, the filter '
                    f'stays {previous.filter_expression!r}: {e}', function=e.function,
                    ret=e.ret, rcl_error=e.rcl_error) from e
            self._user_filter = options
            self._publish_state()

    def configure_nodes_filter(self, node_names: Optional[Sequence[str]] = None) -> bool:
        """
        Receive the parameter events of these nodes only: the newer distros' name (rclpy#1531).

        Accepted so that code moves between distros; it is :meth:`set_parameter_event_filter`
        with :func:`node_filter`.

        :param node_names: Fully qualified node names. ``None`` or empty clears the filter: the
            handler filters on the nodes its callbacks watch again.
        :return: ``True`` if the filter is set; ``False`` if it was refused, which is logged with
            the reason.
        """
        try:
            if node_names:
                options = node_filter(node_names)
                self.set_parameter_event_filter(options.filter_expression,
                                                options.expression_parameters)
            else:
                self.set_parameter_event_filter('')
        except (ContentFilterError, ValueError) as e:
            self._cft_logger.warning(f'configure_nodes_filter({node_names!r}) failed: {e}')
            return False
        return True

    def get_parameter_event_filter(self) -> ContentFilterOptions:
        """
        Return the filter of the ``/parameter_events`` subscription, as the middleware reports it.

        :return: ``(filter_expression, expression_parameters)``; ``('', [])`` when the
            subscription has no content filter.
        """
        return self._reader.read()

    def wait_for_filter(self, timeout_sec: Optional[float] = None) -> bool:
        """
        Wait until the ``/parameter_events`` publishers apply the current filter.

        A filter change travels to the publishers by discovery, and the middleware acknowledges
        nothing: until the change arrives, a publisher applies its previous filter and drops the
        events that one rejects. This method waits for a proof of arrival from every other
        participant (process) that hosts a ``/parameter_events`` publisher known to this node: a
        reply of a parameter service (``get_parameter_types``, asked for no names) of one of its
        nodes, to a client created after the change. Discovery announces that client's response
        reader after the change, in the same ordered stream, and a participant can only reply once
        it has matched that reader, so by then every writer there has processed the change.

        The publishers' nodes must be spun, for their parameter services to reply. Publishers in
        this node's own participant need no proof (Fast DDS does not filter in the writer within a
        process), and publishers that have not matched the subscription yet receive the current
        filter with the match.

        :param timeout_sec: Seconds to wait. Block forever if ``None`` or negative; don't wait
            if 0.
        :return: ``True`` if the current filter is known to be applied; then
            :attr:`parameter_event_filter_state` has ``confirmed=True`` until the next change.
            ``False`` on timeout, if the filter changed meanwhile, or if the handler was destroyed.
        """
        deadline = None
        if timeout_sec is not None and timeout_sec >= 0:
            deadline = time.monotonic() + timeout_sec
        with self._reader.lock:
            if self._reader.ended:
                return False
            target = self._reader.updates
            if self._confirmed_updates == target:
                return True
        probes: dict[str, tuple[bytes, ServiceProbe]] = {}  # service -> (participant, probe)
        turns: dict[bytes, tuple[int, float]] = {}  # participant -> (node index, since when)
        answered: set[bytes] = set()
        own = node_participant(self.node, (PARAMETER_EVENTS_TOPIC, '/rosout'))
        try:
            while True:
                now = time.monotonic()
                pending = {participant: services
                           for participant, services in self._probe_services(own).items()
                           if participant not in answered}
                for participant, services in pending.items():
                    self._probe(participant, services, probes, turns, now)
                for participant, probe in probes.values():
                    if probe.answered():
                        answered.add(participant)
                if not pending:
                    break
                if deadline is not None and now >= deadline:
                    return False
                time.sleep(_PROBE_POLL_S)
        finally:
            for _, probe in probes.values():
                probe.destroy()
        with self._reader.lock:
            if self._reader.ended or self._reader.updates != target:
                return False
            self._confirmed_updates = target
            self._publish_state()
        return True

    def _probe_services(self, own: Optional[bytes]) -> dict[bytes, list[str]]:
        """Map each participant but ``own`` with a parameter event publisher to its nodes' services.

        A participant whose nodes' names are not known yet maps to no service: it stays pending.
        """
        services: dict[bytes, list[str]] = {}
        for info in self.node.get_publishers_info_by_topic(PARAMETER_EVENTS_TOPIC):
            participant = participant_of(info.endpoint_gid)
            if participant == own:
                continue
            candidates = services.setdefault(participant, [])
            if info.node_name.startswith('_NODE_') or info.node_namespace.startswith('_NODE_'):
                continue  # rmw's placeholder while the node's name is not yet discovered
            service = f"{info.node_namespace.rstrip('/')}/{info.node_name}/get_parameter_types"
            if service not in candidates:
                candidates.append(service)
        return services

    def _probe(self, participant: bytes, services: list[str],
               probes: dict[str, tuple[bytes, ServiceProbe]],
               turns: dict[bytes, tuple[int, float]], now: float) -> None:
        """Send, or send again, the probe request to one of ``participant``'s ``services``.

        A node whose service has not replied for _PROBE_TURN_S (not spun, or its server has not
        matched the client yet) hands the probe on to the participant's next node.
        """
        if not services:
            return
        index, since = turns.setdefault(participant, (0, now))
        if now - since >= _PROBE_TURN_S and len(services) > 1:
            index, since = index + 1, now
            turns[participant] = (index, since)
        service = services[index % len(services)]
        if service not in probes:
            probes[service] = (participant, ServiceProbe(
                self.node, GetParameterTypes, service, GetParameterTypes.Request()))
        probes[service][1].send_if_due(now)
