# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Content-filtered subscriptions for any topic: the Jazzy backport of Kilted's rclpy API.

Kilted's rclpy has ``ContentFilterOptions`` and ``Subscription.set_content_filter``; Jazzy's has
neither. These functions give the same capability on Jazzy, through the package's one
filter-changing module, :mod:`cft_action.topics._filtered_reader`.

rmw_fastrtps destroys and recreates the DataReader on the first non-empty filter, and again when the
filter is set back to ``""``. A recreation while an executor waits on the subscription is a
use-after-free, so the first filter is installed here before the subscription is visible to any
executor, later changes are only in place, and ``""`` is refused.
"""

from __future__ import annotations

import uuid
from typing import Callable, Optional, Sequence, Union

import rclpy
from rclpy.callback_groups import CallbackGroup
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.exceptions import InvalidTopicNameException
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.subscription import Subscription
from rclpy.type_support import check_is_valid_msg_type

from cft_action.topics._filtered_reader import apply_filter, get_filter, has_filter, set_filter
from cft_action.topics._program_mark import ProgramMark
from cft_action.topics.message_types import first_primitive_field
from cft_action._rclpy_compat import (declare_qos_parameters, new_rcl_subscription,
                                      register_subscription, validate_qos_or_depth,
                                      validate_topic_name)
from cft_action import _rcl
from cft_action.errors import ContentFilterError, InvalidArgumentError
from cft_action.topics import rate
from cft_action.topics.filters import ContentFilterOptions, Literal, never_match_on

__all__ = [
    'ContentFilterError', 'ContentFilterOptions', 'create_filtered_subscription',
    'get_content_filter', 'is_content_filter_supported', 'is_filtered', 'set_content_filter',
]

#: rmw implementations of Jazzy whose subscriptions support content filtering.
CFT_RMW_IMPLEMENTATIONS = frozenset({
    'rmw_fastrtps_cpp', 'rmw_fastrtps_dynamic_cpp', 'rmw_connextdds',
})

_message_lost_warned = False


def is_content_filter_supported(node: Node) -> bool:
    """Return whether the rmw implementation that ``node`` runs on supports content filtering.

    This is a cheap probe, by rmw identifier; it creates nothing. A filter that the rmw then fails
    to apply is still reported, by :func:`set_content_filter` and
    :func:`create_filtered_subscription`.
    """
    del node  # the rmw is process-wide on Jazzy; the node is taken for a per-node future
    return rclpy.get_rmw_implementation_identifier() in CFT_RMW_IMPLEMENTATIONS


def _validate_on_probe(node: Node, msg_type, qos_profile: QoSProfile, topic: str,
                       expression: str, expression_parameters: Sequence[Literal]) -> None:
    """Let Fast DDS check ``expression`` on a throwaway reader of a private topic.

    rmw_fastrtps destroys the DataReader before it creates the content-filtered topic, and when
    that creation fails it leaves the subscription with a dangling reader, so a rejected *first*
    filter must never reach a real subscription. The probe gets a first filter that is valid by
    construction and never matches, then the user's expression as an in-place change, which Fast
    DDS rejects cleanly. The probe's topic has no publishers, so no writer sees any of this.
    """
    field = first_primitive_field(msg_type)
    if field is None:
        return  # no primitive field to build a first filter on: the real call reports errors
    probe_topic = f'/_cft_action_probe/t{uuid.uuid4().hex}'
    probe = new_rcl_subscription(node, msg_type, probe_topic, qos_profile)
    try:
        with probe:
            set_filter(probe.pointer, probe_topic, never_match_on(field))
            set_filter(probe.pointer, topic, expression, expression_parameters)
    finally:
        probe.destroy_when_not_in_use()


def create_filtered_subscription(
    node: Node,
    msg_type,
    topic: str,
    callback: Callable,
    qos_profile: Union[QoSProfile, int],
    filter_expression: str = '',
    expression_parameters: Sequence[Literal] = (),
    *,
    content_filter_options: Optional[ContentFilterOptions] = None,
    callback_group: Optional[CallbackGroup] = None,
    event_callbacks: Optional[SubscriptionEventCallbacks] = None,
    qos_overriding_options: Optional[QoSOverridingOptions] = None,
    raw: bool = False,
    max_rate: Optional[float] = None,
    poll: Optional[int] = None,
) -> Subscription:
    """
    Create a subscription whose messages are filtered by the middleware.

    Takes the arguments of :meth:`rclpy.node.Node.create_subscription`, plus the filter. The filter
    is installed before the subscription is added to the node, so no executor ever waits on it
    unfiltered and no sample arrives that does not match.

    Fast DDS 2.14.5 (not 2.14.6) counts samples that the writer filtered out as *lost*: a
    ``message_lost`` callback in ``event_callbacks`` would report them as false alarms, so passing
    one logs a warning.

    :param node: The node to create the subscription on.
    :param msg_type: The type of ROS messages the subscription will subscribe to.
    :param topic: The name of the topic the subscription will subscribe to.
    :param callback: A user-defined callback function that is called when a message is
        received by the subscription.
    :param qos_profile: A QoSProfile or a history depth to apply to the subscription.
    :param filter_expression: A DDS-SQL expression over the message fields, for example
        ``"data > %0"``. Array members must be indexed: ``"goal_id.uuid[0] = 7"``.
    :param expression_parameters: Values for ``%0`` .. ``%99``. Python values and bare strings are
        turned into DDS literals by :func:`cft_action.topics.filters.dds_literal`: ``hello`` is sent
        as
        ``'hello'``.
    :param content_filter_options: The filter as Kilted's ``Node.create_subscription`` takes it,
        ``ContentFilterOptions(filter_expression, expression_parameters)``, instead of the two
        arguments above, so that code moves between distros.
    :param callback_group: The callback group for the subscription. If ``None``, then the
        default callback group for the node is used.
    :param event_callbacks: User-defined callbacks for middleware events.
    :param qos_overriding_options: Options to allow overriding QoS parameters.
    :param raw: If ``True``, then received messages will be stored in raw binary
        representation.
    :param max_rate: At most this many messages per second from each publisher, decided by the
        publisher where it runs under ``cft-action guard`` (:mod:`cft_action.topics.rate`). Takes
        no expression: a reader has one filter class, and the rate's is not DDS-SQL.
    :param poll: Receive only polled messages: this many of each publisher now (``0``: none), more
        with :func:`cft_action.poll`. Combines with ``max_rate``; takes no expression either.
    :return: An ordinary :class:`rclpy.subscription.Subscription`.
    :raises ContentFilterError: if the filter cannot be applied; the message names the expression
        and carries rcl's error string. No subscription is left behind.
    :raises InvalidArgumentError: if ``max_rate`` is not positive and finite, ``poll`` is not a
        whole number ``>= 0``, or either comes with an expression.
    """
    if max_rate is not None or poll is not None:
        if filter_expression or expression_parameters or content_filter_options is not None:
            raise InvalidArgumentError(
                'max_rate and poll take no filter expression: a subscription has one filter '
                "class, and theirs decides per publisher, not on the message's fields")
        return _subscribe_rate_limited(
            node, msg_type, topic, callback, qos_profile, rate.RateFilter(max_rate, poll),
            callback_group=callback_group, event_callbacks=event_callbacks,
            qos_overriding_options=qos_overriding_options, raw=raw)
    if content_filter_options is not None:
        if filter_expression or expression_parameters:
            raise InvalidArgumentError('give the filter either as content_filter_options or as '
                                       'filter_expression and expression_parameters, not both')
        filter_expression, expression_parameters = content_filter_options
    if not filter_expression:
        raise ContentFilterError('a filtered subscription needs a non-empty filter_expression; '
                                 'use Node.create_subscription for an unfiltered one')
    return subscribe_filtered(
        node, msg_type, topic, callback, qos_profile, filter_expression, expression_parameters,
        callback_group=callback_group, event_callbacks=event_callbacks,
        qos_overriding_options=qos_overriding_options, raw=raw)[0]


def _subscribe_rate_limited(node: Node, msg_type, topic: str, callback: Callable,
                            qos_profile: Union[QoSProfile, int], rate_filter: rate.RateFilter,
                            **options) -> Subscription:
    """A subscription filtered by ``rate_filter``: with the library's rate class, or, where that
    cannot be used (another rmw, the class not available), by a gate in Python, said once."""
    reason = ''
    if not is_content_filter_supported(node):
        reason = f'{rclpy.get_rmw_implementation_identifier()} has no content filtering'
    else:
        reason = _rcl.filter_class_status()
    if not reason and not _rcl.filter_class_accepts(_rcl.RATE_FILTER_CLASS,
                                                     rate_filter.expression()):
        reason = ('the rate filter class is not in this build of cft_action (it was built '
                  'without the Fast DDS headers)')
    if not reason:
        try:
            subscription, rate_filter.created = subscribe_filtered(
                node, msg_type, topic, callback, qos_profile, rate_filter.expression(), (),
                filter_class=_rcl.RATE_FILTER_CLASS, sql_expression=False, **options)
        except ContentFilterError as e:
            if e.function is None:
                raise  # not the middleware's refusal: a bad topic, or the like
            reason = str(e)
    if reason:
        rate_filter.reason = reason
        subscription = node.create_subscription(msg_type, topic, rate_filter.gate(callback),
                                                qos_profile, **options)
        _mark_rate_reader(node, subscription, rate_filter)
    rate.register(subscription, rate_filter)
    return subscription


def _mark_rate_reader(node: Node, subscription: Subscription,
                      rate_filter: rate.RateFilter) -> None:
    """Where the rate class cannot filter ``subscription``'s reader: mark the reader so that guarded
    Fast DDS 3.3+ publishers apply the rule (the callback's gate applies it to every publisher
    anyway), and say once where the rule is applied."""
    rate_filter.mark, refused = ProgramMark.install(subscription, _rcl.RATE_FILTER_CLASS,
                                                    rate_filter.writer_expression())
    node.get_logger().info(
        f'{subscription.topic_name}: max_rate and poll are applied in this process (per '
        'publisher where rclpy says which one sent a message), since its DDS reader cannot '
        f'filter: {rate_filter.reason}; '
        + ('publishers run under cft-action guard (Fast DDS 3.3+) apply them too'
           if not refused else f'publishers do not: {refused}'), once=True)


def subscribe_filtered(
    node: Node,
    msg_type,
    topic: str,
    callback: Callable,
    qos_profile: Union[QoSProfile, int],
    filter_expression: str,
    expression_parameters: Sequence[Literal],
    *,
    filter_class: Optional[str] = None,
    sql_expression: bool = True,
    callback_group: Optional[CallbackGroup] = None,
    event_callbacks: Optional[SubscriptionEventCallbacks] = None,
    qos_overriding_options: Optional[QoSOverridingOptions] = None,
    raw: bool = False,
) -> tuple[Subscription, Optional[int]]:
    """:func:`create_filtered_subscription` with a non-empty filter, optionally in one of the
    library's filter classes (:func:`cft_action._rcl.set_content_filter`).

    :param sql_expression: False for an expression of the rate class, which is not DDS-SQL.
    :return: the subscription, and the class's filter object that this process created for it
        (None for DDS-SQL, or when the preloaded guard created it).
    """
    # What follows mirrors Node.create_subscription, with the filter set between the creation of
    # the rcl subscription and its registration with the node.
    qos_profile = validate_qos_or_depth(node, qos_profile)
    callback_group = callback_group or node.default_callback_group
    try:
        final_topic = node.resolve_topic_name(topic)
    except RuntimeError:
        try:
            validate_topic_name(node, topic)
        except InvalidTopicNameException as ex:
            raise ex from None
        raise
    declare_qos_parameters(node, final_topic, qos_profile,
                           qos_overriding_options or QoSOverridingOptions([]))
    check_is_valid_msg_type(msg_type)
    if filter_class is None:  # a class's expressions are checked by its own grammar
        _validate_on_probe(node, msg_type, qos_profile, final_topic, filter_expression,
                           expression_parameters)
    subscription_object = new_rcl_subscription(node, msg_type, topic, qos_profile)
    try:
        with subscription_object:
            created = apply_filter(subscription_object.pointer, final_topic, filter_expression,
                                   expression_parameters, filter_class=filter_class,
                                   sql_expression=sql_expression)[1]
        subscription = Subscription(
            subscription_object, msg_type, topic, callback, callback_group, qos_profile, raw,
            event_callbacks=event_callbacks or SubscriptionEventCallbacks())
    except Exception:
        subscription_object.destroy_when_not_in_use()
        raise
    if event_callbacks is not None and event_callbacks.message_lost is not None:
        _warn_message_lost(node)
    callback_group.add_entity(subscription)
    register_subscription(node, subscription)
    # rclpy 7.1 annotates event_handlers as one EventHandler; it is a list of them.
    for event_handler in subscription.event_handlers:  # type: ignore[attr-defined]
        node.add_waitable(event_handler)
    return subscription, created


def _warn_message_lost(node: Node) -> None:
    global _message_lost_warned
    if not _message_lost_warned:
        _message_lost_warned = True
        node.get_logger().warning(
            'message_lost callback on a content-filtered subscription: Fast DDS 2.14.5 counts the '
            'samples that the writer filtered out as lost (2.14.6 does not), so this callback may '
            'report false alarms')


def set_content_filter(subscription: Subscription, filter_expression: str,
                       expression_parameters: Sequence[Literal] = ()) -> None:
    """
    Change the filter of a subscription made by :func:`create_filtered_subscription`.

    The change is made in place, so it is safe while an executor spins the subscription. It travels
    to the publishers by discovery; until it arrives they apply the previous filter.

    :param subscription: A filtered subscription.
    :param filter_expression: The new, non-empty DDS-SQL expression.
    :param expression_parameters: Values for ``%0`` .. ``%99``, quoted as DDS literals as needed.
    :raises ContentFilterError: if the expression is empty, if the subscription has no filter yet
        (rmw_fastrtps would recreate its reader under a waiting executor), or if rcl rejects it;
        the subscription then keeps its previous filter.
    """
    with subscription.handle:
        pointer = subscription.handle.pointer
        if not has_filter(pointer):
            raise ContentFilterError(
                f'{subscription.topic_name} has no content filter yet; installing a first one '
                'recreates the DataReader, so create it with create_filtered_subscription')
        set_filter(pointer, subscription.topic_name, filter_expression, expression_parameters)


def get_content_filter(subscription: Subscription) -> ContentFilterOptions:
    """Return the subscription's filter as ``(filter_expression, expression_parameters)``.

    :raises ContentFilterError: if the rmw has no content filtering, or rcl fails.
    """
    with subscription.handle:
        return get_filter(subscription.handle.pointer)


def is_filtered(subscription: Subscription) -> bool:
    """Return whether the middleware applies a content filter to ``subscription``."""
    with subscription.handle:
        return has_filter(subscription.handle.pointer)
