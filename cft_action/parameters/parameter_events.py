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
events enabled, not only at the watched ones. With a DDS-SQL filter, Fast DDS 2.14 can crash a
process that publishes at that moment (eProsima/Fast-DDS#4878, docs/INTERNALS.md section 10;
measured in docs/BENCHMARKS.md, "Parameter events"). So the handler's filter uses the library's
own class, ``CFT_ACTION_NODE`` (docs/INTERNALS.md section 16): a node that nobody put under the
guard does not know it, keeps no filter for this handler and sends it every event, which the
handler's DDS reader drops; a node under :mod:`cft_action.guard` filters on its side. An
expression of one's own (:meth:`ParameterEventHandler.set_parameter_event_filter`) is DDS-SQL,
with ``writer_filtering='any'``: change it rarely, or run the nodes under the guard.
"""

from __future__ import annotations

from typing import Callable, Optional, Sequence, Union

from rcl_interfaces.msg import ParameterEvent
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

from cft_action.parameters._parameter_event_filter import (
    ALL_NODES,
    NO_NODES,
    node_filter,
    PARAMETER_EVENTS_TOPIC,
    ParameterEventFilter,
    ParameterEventFilterState,
)
from cft_action._rclpy_compat import PromptLogger, set_parameter_event_callbacks
from cft_action.topics.filters import ContentFilterOptions, Literal
from cft_action.topics.subscription import is_content_filter_supported

__all__ = [
    'ALL_NODES', 'NO_NODES', 'ParameterEventFilterState', 'ParameterEventHandler',
    'node_filter', 'PARAMETER_EVENTS_TOPIC',
]


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
        *,
        writer_filtering: str = 'guarded',
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
        :param qos_profile: A QoSProfile or a history depth to apply to the subscription (a depth
            gives KEEP_LAST of that depth, and every other QoS setting its default).
        :param callback_group: The callback group for the subscription. If ``None``, then the
            default callback group for the node is used.
        :param event_callbacks: User-defined callbacks for middleware events (Fast DDS 2.14.5
            counts the events that guarded publishers filtered out as *lost*).
        :param qos_overriding_options: Options to customize QoS parameter overrides.
        :param raw: If ``True``, then received messages will be stored in raw binary
            representation.
        :param writer_filtering: As for :class:`cft_action.ActionClient`: ``'guarded'`` (default),
            the library's node class, which only nodes under the guard filter on their side;
            ``'any'``, DDS-SQL, which :meth:`set_parameter_event_filter` needs beyond node names.
        """
        # rclpy's constructor would create an unfiltered subscription, and giving that a first
        # filter later recreates its DataReader; so its three attributes are set here instead.
        self.node = node
        self.qos_profile = qos_profile  # type: ignore[assignment]  # rclpy types it QoSProfile only
        self._rclpy_callbacks = set_parameter_event_callbacks(self)  # what its methods use
        self._cft_logger = PromptLogger(node.get_logger().get_child('cft_action'))
        self._filter = ParameterEventFilter(node, self._cft_logger, writer_filtering)
        self.parameter_event_subscription = self._filter.subscribe(
            node, self._rclpy_callbacks.event_callback, is_content_filter_supported(node),
            qos_profile=self.qos_profile, callback_group=callback_group,
            event_callbacks=event_callbacks, qos_overriding_options=qos_overriding_options,
            raw=raw)

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
        self._filter.watch(handle.node_name)
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
        self._filter.unwatch(handle.node_name)

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
        self._filter.count_event_callbacks(+1)
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
        self._filter.count_event_callbacks(-1)

    def destroy(self) -> None:
        """Destroy the subscription to ``/parameter_events``."""
        self._filter.detach()
        super().destroy()

    # --- filter API -------------------------------------------------------------------------------

    @property
    def parameter_event_filter_state(self) -> ParameterEventFilterState:
        """The filter's mode, whether it is active and why not, and its counters (read-only)."""
        return self._filter.state

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
        self._filter.set_user(filter_expression, expression_parameters)

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
        return self._filter.configure_nodes(node_names)

    def get_parameter_event_filter(self) -> ContentFilterOptions:
        """
        Return the filter of the ``/parameter_events`` subscription, as the middleware reports it.

        :return: ``(filter_expression, expression_parameters)``; ``('', [])`` when the
            subscription has no content filter.
        """
        return self._filter.reader.read()

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
        return self._filter.wait(timeout_sec)
