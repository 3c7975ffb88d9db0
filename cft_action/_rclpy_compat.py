# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Every touch of an rclpy private name, in one module, checked once against the installed rclpy.

cft_action is a drop-in for rclpy 7.1 (Jazzy) classes, and a drop-in has to reach inside them: the
action client's bookkeeping of goals and callbacks, the node's subscription registry, the rcl
entities of the C extension. Those names are private, so rclpy may change them in any release.
They are named here and nowhere else, and checked when this module is imported:

- a name that is missing raises :class:`~cft_action.errors.BindingUnavailable`, which names it and
  the tested version, instead of an ``AttributeError`` deep inside a callback later;
- a version other than the tested one, with every name present, logs one warning.
"""

from __future__ import annotations

import importlib.metadata
import sys
import threading
import weakref
from typing import Any, Callable, Iterator, Optional

import rclpy.qos_overriding_options
from rclpy.action import ActionClient as _RclpyActionClient
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.logging import get_logger, LoggingSeverity
from rclpy.node import Node
from rclpy.parameter_event_handler import ParameterEventHandler as _RclpyParameterEventHandler
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription
from rclpy.task import Future

from cft_action.errors import BindingUnavailable

__all__ = ['TESTED_RCLPY', 'CompatActionClient', 'PromptLogger', 'RCLError',
           'declare_qos_parameters',
           'new_rcl_client', 'new_rcl_subscription', 'register_subscription',
           'set_parameter_event_callbacks', 'validate_qos_or_depth', 'validate_topic_name']

#: The rclpy minor version the package is tested with.
TESTED_RCLPY = (7, 1)

#: Members of rclpy classes that this module uses: (owner, name).
_REQUIRED: tuple[tuple[Any, str], ...] = (
    (_RclpyActionClient, '_cancel_goal_async'),
    (_RclpyActionClient, '_get_result_async'),
    (_RclpyActionClient, '_remove_pending_request'),
    (_RclpyActionClient, '_remove_pending_result_request'),
    (_RclpyActionClient, '_generate_random_uuid'),
    (Future, '_set_executor'),
    (Node, '_validate_qos_or_depth_parameter'),
    (Node, '_validate_topic_or_service_name'),
    (Node, '_wake_executor'),
    (rclpy.qos_overriding_options, '_declare_qos_parameters'),
    (_RclpyParameterEventHandler, 'Callbacks'),
    (_rclpy, 'Subscription'),
    (_rclpy, 'Client'),
    (_rclpy, 'RCLError'),
    (_rclpy, 'rclpy_logging_rcutils_log'),
)

#: Instance attributes that rclpy's ActionClient sets in its constructor, checked on each one.
#: (``_is_feedback_ready`` and ``_is_result_response_ready`` are set by its ``is_ready``.)
_ACTION_CLIENT_STATE = ('_action_type', '_client_handle', '_node', '_feedback_callbacks',
                        '_futures', '_pending_result_requests', '_goal_sequence_number_to_goal_id',
                        '_result_sequence_number_to_goal_id')


def _installed_version() -> tuple[int, ...]:
    try:
        text = importlib.metadata.version('rclpy')
    except importlib.metadata.PackageNotFoundError:
        return ()
    return tuple(int(part) for part in text.split('.')[:2] if part.isdigit())


def _check() -> None:
    version = _installed_version()
    tested = '.'.join(map(str, TESTED_RCLPY))
    missing = [f'{getattr(owner, "__name__", owner)}.{name}' for owner, name in _REQUIRED
               if not hasattr(owner, name)]
    if missing:
        raise BindingUnavailable(
            f'rclpy {".".join(map(str, version)) or "(unknown version)"} lacks '
            f'{", ".join(missing)}, which cft_action uses; it is tested with rclpy {tested}.x')
    if version[:2] != TESTED_RCLPY:
        get_logger('cft_action').warning(
            f'rclpy {".".join(map(str, version))} is not the tested {tested}.x; the private '
            'names cft_action uses are all present')


_check()

RCLError = _rclpy.RCLError


class PromptLogger:
    """A node's logger whose calls return at once, for code that runs between goal sends.

    rclpy's :class:`RcutilsLogger` finds its caller with ``inspect.getframeinfo``, which on the
    first call in a process resolves the path of every loaded module (for how long: the README,
    "Differences from rclpy"). A client that logs inside ``send_goal_async`` stalls its executor
    for that long, and a feedback queue of rclpy's default depth, 10 for all goals, then drops the
    first feedback of the goals sent just before (docs/INTERNALS.md, "Logging never stalls").
    This logger hands rcutils the caller of its method straight from the frame, which is what
    rclpy reports too, and has no filters (``once``, ``throttle``).

    :param logger: the logger to write to, e.g. ``node.get_logger().get_child('cft_action')``.
    """

    def __init__(self, logger: RcutilsLogger) -> None:
        self.name: str = logger.name
        self._logger = logger

    def _log(self, severity: LoggingSeverity, message: str) -> None:
        if not self._logger.is_enabled_for(severity):
            return
        caller = sys._getframe(2)
        _rclpy.rclpy_logging_rcutils_log(severity, self.name, message, caller.f_code.co_name,
                                         caller.f_code.co_filename, caller.f_lineno)

    def debug(self, message: str) -> None:
        """Log ``message`` with DEBUG severity."""
        self._log(LoggingSeverity.DEBUG, message)

    def info(self, message: str) -> None:
        """Log ``message`` with INFO severity."""
        self._log(LoggingSeverity.INFO, message)

    def warning(self, message: str) -> None:
        """Log ``message`` with WARN severity."""
        self._log(LoggingSeverity.WARN, message)

    def error(self, message: str) -> None:
        """Log ``message`` with ERROR severity."""
        self._log(LoggingSeverity.ERROR, message)


class _ExecutorProbe:
    """The first item :class:`BoundFutures` yields, which learns the executor that iterates."""

    __slots__ = ('executor',)

    def __init__(self) -> None:
        self.executor: Any = None

    def _set_executor(self, executor: Any) -> None:
        self.executor = executor


class BoundFutures:
    """rclpy's ``Waitable._futures`` for an action client: each future bound once per executor.

    At every wake of a waitable, rclpy's executor calls ``_set_executor`` on every future in
    ``_futures`` (``Executor._take_waitable``), so that the futures' done callbacks run in it, and
    ``remove_future`` removes from a list. An action client keeps there every request in flight,
    so with G goals in flight each wake costs O(G), and so does each response. Measured with
    ``benchmarks/many_goals.py`` at 2,000 goals: about 30 % of the client's CPU, 3.25 million
    calls. Here the iteration first yields a probe, on which the executor's loop calls
    ``_set_executor`` before it asks for the next item; then only the futures not yet bound to
    that executor. When another executor iterates, every future is bound again, as rclpy would.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._unbound: dict[int, Future] = {}
        self._bound: dict[int, Future] = {}
        self._executor: Optional[weakref.ReferenceType] = None  # the one _bound is bound to

    def append(self, future: Future) -> None:
        """``Waitable.add_future``."""
        with self._lock:
            self._unbound[id(future)] = future

    def remove(self, future: Future) -> None:
        """``Waitable.remove_future``; ValueError if it is not there, as ``list.remove``."""
        with self._lock:
            if self._unbound.pop(id(future), None) is None and \
                    self._bound.pop(id(future), None) is None:
                raise ValueError(f'{future!r} is not among the futures of this waitable')

    def __len__(self) -> int:
        with self._lock:
            return len(self._unbound) + len(self._bound)

    def __contains__(self, future: object) -> bool:
        with self._lock:
            return id(future) in self._unbound or id(future) in self._bound

    def __iter__(self) -> Iterator[Any]:
        probe = _ExecutorProbe()
        yield probe
        executor = probe.executor
        with self._lock:
            if executor is None or self._executor is None or self._executor() is not executor:
                self._unbound.update(self._bound)
                self._bound.clear()
                self._executor = None if executor is None else weakref.ref(executor)
            binding = list(self._unbound.values())
            if self._executor is not None:
                self._bound.update(self._unbound)
                self._unbound.clear()
        yield from binding


class CompatActionClient(_RclpyActionClient):
    """rclpy's ActionClient, with its private state under names of this package's own.

    :class:`cft_action.ActionClient` derives from it and uses only these members.

    rclpy's constructor creates the rcl action client and then hands the client to
    ``Node.add_waitable``, where an executor can first see it; :meth:`_cft_before_first_wait`
    runs in between.

    rclpy sends a request (goal, result, cancel) and only then registers its sequence number, so
    under a multithreaded executor another thread can take and execute the response in between:
    rclpy then logs "Ignoring unexpected goal response" and the request's future never completes
    (measured with plain rclpy: 3 client processes of coroutines on 4-thread executors). Here a
    request holds ``request_lock`` from its send to its registration, and responses are taken
    under it (:meth:`_cft_take_data`).

    :param request_lock: The lock for that; a re-entrant one of its own if None.
    """

    def __init__(self, node: Node, *args: Any, request_lock: Optional[Any] = None,
                 **kwargs: Any) -> None:
        self._cft_request_lock = request_lock or threading.RLock()
        shadowed = node.__dict__.get('add_waitable')
        add_waitable = node.add_waitable

        def hook_then_add(waitable: Any) -> None:
            if waitable is self:
                self._cft_before_first_wait()
            add_waitable(waitable)

        node.add_waitable = hook_then_add  # type: ignore[method-assign]
        try:
            super().__init__(node, *args, **kwargs)
        finally:
            if shadowed is None:
                del node.add_waitable
            else:
                node.add_waitable = shadowed  # type: ignore[method-assign]
        missing = [name for name in _ACTION_CLIENT_STATE if not hasattr(self, name)]
        if missing:
            raise BindingUnavailable(
                f'rclpy ActionClient has no {", ".join(missing)}; cft_action is tested with '
                f'rclpy {".".join(map(str, TESTED_RCLPY))}.x')
        self._futures: Any = BoundFutures()

    def _cft_before_first_wait(self) -> None:
        """Runs once the rcl entities exist, before any executor can see them."""

    # --- requests registered before their responses can be taken ---------------------------------

    def _get_result_async(self, goal_handle: Any) -> Future:
        with self._cft_request_lock:
            return super()._get_result_async(goal_handle)

    def _cancel_goal_async(self, goal_handle: Any) -> Future:
        with self._cft_request_lock:
            return super()._cancel_goal_async(goal_handle)

    def take_data(self) -> dict:
        """Take stuff from lower level so the wait set doesn't immediately wake again."""
        with self._cft_request_lock:
            return self._cft_take_data()

    def _cft_take_data(self) -> dict:
        """rclpy's take_data; called with the request lock held."""
        return super().take_data()

    # Read before rclpy's constructor has run (from Node.add_waitable), so no check above yet.
    @property
    def _cft_client_handle(self) -> Any:
        return self._client_handle

    @property
    def _cft_action_type(self) -> Any:
        return self._action_type

    @property
    def _cft_node(self) -> Node:
        return self._node

    @property
    def _cft_feedback_callbacks(self) -> dict[bytes, Callable]:
        """Goal UUID -> feedback callback; rclpy delivers feedback only to goals in here."""
        return self._feedback_callbacks

    def _cft_goal_id_of_goal_request(self, sequence_number: int) -> Any:
        return self._goal_sequence_number_to_goal_id.get(sequence_number)

    def _cft_goal_id_of_result_request(self, sequence_number: int) -> Any:
        return self._result_sequence_number_to_goal_id.get(sequence_number)

    def _cft_take_readiness(self) -> tuple[bool, bool]:
        """``(result response ready, feedback ready)``, as the last wait found them."""
        return self._is_result_response_ready, self._is_feedback_ready

    def _cft_feedback_ready(self) -> bool:
        return self._is_feedback_ready

    def _cft_clear_readiness(self) -> None:
        """Make rclpy's take_data take neither the result response nor the feedback."""
        self._is_result_response_ready = self._is_feedback_ready = False

    def _cft_claim_status(self) -> bool:
        """Whether the last wait found status; rclpy's take_data then does not take it."""
        ready, self._is_status_ready = self._is_status_ready, False
        return ready

    #: Told the UUID of every goal request just before it is sent, if set.
    _cft_goal_sending: Optional[Callable[[bytes], None]] = None

    def send_goal_async(self, goal: Any, feedback_callback: Optional[Callable] = None,
                        goal_uuid: Optional[Any] = None) -> Future:
        """rclpy's, with the goal's UUID chosen here and told to ``_cft_goal_sending``, under the
        request lock."""
        if goal_uuid is None:
            goal_uuid = self._generate_random_uuid()
        with self._cft_request_lock:
            if self._cft_goal_sending is not None:
                self._cft_goal_sending(bytes(goal_uuid.uuid))
            return super().send_goal_async(goal, feedback_callback, goal_uuid)

    def _remove_pending_result_request(self, future: Future) -> None:
        # rclpy's done callback of every result request.
        self._cft_result_request_done(future)

    def _cft_result_request_done(self, future: Future) -> None:
        """A result request finished: by default as rclpy, which also forgets the callback."""
        super()._remove_pending_result_request(future)

    def _cft_forget_result_request(self, future: Future) -> Optional[Any]:
        """Forget a finished result request, and nothing else; the goal id it was for."""
        sequence_number = self._remove_pending_request(future, self._pending_result_requests)
        return self._result_sequence_number_to_goal_id.pop(sequence_number, None)


def validate_qos_or_depth(node: Node, qos_profile: Any) -> QoSProfile:
    """A QoSProfile from a profile or a depth, as ``Node.create_subscription`` takes it."""
    return node._validate_qos_or_depth_parameter(qos_profile)


def validate_topic_name(node: Node, topic: str) -> None:
    """Raise rclpy's InvalidTopicNameException for a name that does not resolve."""
    node._validate_topic_or_service_name(topic)


def declare_qos_parameters(node: Node, topic: str, qos_profile: QoSProfile,
                           options: rclpy.qos_overriding_options.QoSOverridingOptions) -> None:
    """Declare the QoS override parameters of a subscription, as ``Node.create_subscription``."""
    rclpy.qos_overriding_options._declare_qos_parameters(
        Subscription, node, topic, qos_profile, options)


def new_rcl_subscription(node: Node, msg_type: Any, topic: str, qos_profile: QoSProfile) -> Any:
    """An rcl subscription of the C extension, not yet known to the node."""
    with node.handle:
        return _rclpy.Subscription(node.handle, msg_type, topic, qos_profile.get_c_qos_profile())


def register_subscription(node: Node, subscription: Subscription) -> None:
    """Add a subscription to the node, where executors find it, and wake them."""
    node._subscriptions.append(subscription)
    node._wake_executor()


def new_rcl_client(node: Node, srv_type: Any, service_name: str, qos_profile: QoSProfile) -> Any:
    """An rcl service client of the C extension, not known to the node or any executor."""
    with node.handle:
        return _rclpy.Client(node.handle, srv_type, service_name,
                             qos_profile.get_c_qos_profile())


def set_parameter_event_callbacks(handler: _RclpyParameterEventHandler) -> Any:
    """Give a handler rclpy's callback registry, which its inherited methods use; return it."""
    handler._callbacks = _RclpyParameterEventHandler.Callbacks()
    return handler._callbacks
