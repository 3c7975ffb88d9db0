# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The commands ``cft-action topic echo|hz|bw``: sessions, filters, rates and output.

Messages are printed by :mod:`cft_action.message_yaml`, and filters are checked against
:func:`cft_action.message_types.message_schema`, the kinds of a message's fields as Fast DDS sees
them.

The filter of every command is applied by the middleware. If it cannot be, the command exits with
:data:`EXIT_FILTER` and the reason, and prints no message: there is no silent fallback to unfiltered
messages. ``--filter-fallback=client`` is the explicit opt-in to evaluating the expression in this
process when the rmw implementation has no content filtering.
"""

from __future__ import annotations

import argparse
import copy
import importlib
import math
import os
import sys
import time
from collections import deque
from typing import Callable, Optional


from cft_action import sql
from cft_action.errors import CftActionError
from cft_action.message_types import is_message, message_schema
from cft_action.message_yaml import message_to_yaml

__all__ = [
    'EXIT_ERROR', 'EXIT_FILTER', 'FilterUnavailable', 'TopicToolError', 'get_message_class',
    'run_bw', 'run_echo', 'run_hz',
]

#: Exit status when the filter cannot be applied (and for command-line usage errors, as argparse).
EXIT_FILTER = 2
#: Exit status of any other failure: an unknown type, a topic that never appears.
EXIT_ERROR = 1

DEFAULT_TRUNCATE_LENGTH = 128


class TopicToolError(CftActionError):
    """A failure that ends a command with a message and :attr:`exit_code`.

    No builtin fits every case (an unknown type, a topic that never appears), so it has none.
    """

    exit_code = EXIT_ERROR


class FilterUnavailable(TopicToolError):
    """The filter cannot be applied: the command exits without printing any message."""

    exit_code = EXIT_FILTER


# --- message types --------------------------------------------------------------------------------

def get_message_class(type_name: str):
    """Import the message class named ``pkg/msg/Type`` (or ``pkg/Type``).

    :raises TopicToolError: naming the type and what is wrong with it.
    """
    parts = type_name.split('/')
    if len(parts) == 2:
        package, interface, name = parts[0], 'msg', parts[1]
    elif len(parts) == 3:
        package, interface, name = parts
    else:
        raise TopicToolError(f"The passed message type '{type_name}' is invalid: expected "
                             "'package/msg/Type', e.g. 'std_msgs/msg/String'")
    if interface != 'msg' or not all(parts):
        raise TopicToolError(f"The passed message type '{type_name}' is invalid: expected "
                             "'package/msg/Type', e.g. 'std_msgs/msg/String'")
    try:
        module = importlib.import_module(f'{package}.{interface}')
    except ImportError as e:
        raise TopicToolError(f"The passed message type '{type_name}' is invalid: cannot import "
                             f'{package}.{interface} ({e})') from None
    msg_type = getattr(module, name, None)
    if msg_type is None or not is_message(msg_type):
        raise TopicToolError(f"The passed message type '{type_name}' is invalid: {package}."
                             f'{interface} has no message {name}')
    return msg_type


# --- the commands ---------------------------------------------------------------------------------

class _Session:
    """An rclpy context with one hidden node and an executor, for one command."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node(f'_cft_action_topic_{os.getpid()}', context=self.context,
                         start_parameter_services=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def close(self) -> None:
        import rclpy
        try:
            self.executor.shutdown(timeout_sec=1)
            self.node.destroy_node()
        finally:
            if self.context.ok():
                rclpy.shutdown(context=self.context)

    def spin_once(self, timeout: float) -> None:
        self.executor.spin_once(timeout_sec=max(0.0, timeout))


class _Deadline:
    def __init__(self, seconds: Optional[float]) -> None:
        self.end = None if seconds is None else time.monotonic() + seconds

    def remaining(self, cap: float = 0.1) -> float:
        if self.end is None:
            return cap
        return min(cap, self.end - time.monotonic())

    def passed(self) -> bool:
        return self.end is not None and time.monotonic() >= self.end


def _resolve(session: _Session, topic: str, type_name: Optional[str], deadline: _Deadline):
    """Return the fully qualified topic and its message class, from the name or from the graph."""
    from rclpy.expand_topic_name import expand_topic_name
    from rclpy.validate_full_topic_name import validate_full_topic_name

    try:
        full = expand_topic_name(topic, session.node.get_name(), session.node.get_namespace())
        validate_full_topic_name(full)
    except Exception as e:  # noqa: BLE001 - rclpy raises several kinds for a bad name
        raise TopicToolError(f'invalid topic name {topic!r}: {e}') from None
    if type_name:
        return full, get_message_class(type_name)
    warn_at = time.monotonic() + 1.0  # discovery usually needs a moment: warn only after it
    warned = False
    while True:
        types = dict(session.node.get_topic_names_and_types()).get(full)
        if types:
            if len(types) > 1:
                raise TopicToolError(f"cannot tell the type of '{full}', which has several: "
                                     f'{", ".join(types)}; give one')
            return full, get_message_class(types[0])
        if deadline.passed():
            raise TopicToolError(f"could not determine the type of '{full}': it does not appear "
                                 'in the graph; give its type, e.g. std_msgs/msg/String')
        if not warned and time.monotonic() >= warn_at:
            print(f'WARNING: topic [{full}] does not appear to be published yet', file=sys.stderr,
                  flush=True)
            warned = True
        session.spin_once(deadline.remaining(0.1))


def _choose_qos(session: _Session, topic: str, args: argparse.Namespace):
    """ros2cli's choice: a preset, made reliable or transient-local when every publisher is."""
    from rclpy.qos import (QoSDurabilityPolicy, QoSHistoryPolicy, QoSPresetProfiles,
                           QoSReliabilityPolicy)

    profile = copy.copy(QoSPresetProfiles.get_from_short_key(args.qos_profile))
    publishers = session.node.get_publishers_info_by_topic(topic)
    if args.qos_reliability is not None:
        profile.reliability = QoSReliabilityPolicy.get_from_short_key(args.qos_reliability)
    elif publishers:
        reliable = all(p.qos_profile.reliability == QoSReliabilityPolicy.RELIABLE
                       for p in publishers)
        profile.reliability = (QoSReliabilityPolicy.RELIABLE if reliable
                               else QoSReliabilityPolicy.BEST_EFFORT)
    if args.qos_durability is not None:
        profile.durability = QoSDurabilityPolicy.get_from_short_key(args.qos_durability)
    elif publishers:
        latched = all(p.qos_profile.durability == QoSDurabilityPolicy.TRANSIENT_LOCAL
                      for p in publishers)
        profile.durability = (QoSDurabilityPolicy.TRANSIENT_LOCAL if latched
                              else QoSDurabilityPolicy.VOLATILE)
    if args.qos_history is not None:
        profile.history = QoSHistoryPolicy.get_from_short_key(args.qos_history)
    if args.qos_depth is not None:
        profile.depth = args.qos_depth
    return profile


def _subscribe(session: _Session, topic: str, msg_type, qos, callback: Callable,
               args: argparse.Namespace, *, raw: bool = False):
    """Subscribe with the filter of ``args`` applied by the middleware, or raise FilterUnavailable.

    The expression is checked first by :mod:`cft_action.sql`, so that a bad one is reported with its
    reason and a LIKE pattern that would abort Fast DDS never reaches it. With
    ``--filter-fallback=client`` and an rmw implementation without content filtering, the
    expression is evaluated here on each message instead, and a warning says so.
    """
    import rclpy
    from cft_action.filters import dds_literals
    from cft_action.subscription import (ContentFilterError, create_filtered_subscription,
                                         is_content_filter_supported)

    # Fast DDS rejects an expression that starts or ends with a space, which a shell makes easy
    expression = None if args.filter is None else args.filter.strip()
    if expression is None:
        if args.params:
            raise FilterUnavailable('--params needs --filter')
        return session.node.create_subscription(msg_type, topic, callback, qos, raw=raw)
    try:
        parameters = dds_literals(args.params or ())
    except (TypeError, ValueError) as e:
        raise FilterUnavailable(f'cannot filter {topic}: content filter {expression!r}: bad '
                                f'expression parameter: {e}') from None
    try:
        client_filter = sql.compile_filter(expression, parameters, message_schema(msg_type))
    except sql.FilterError as e:
        raise FilterUnavailable(f'cannot filter {topic}: {e.detail}') from None
    for warning in client_filter.warnings:
        print(f'WARNING: {warning}', file=sys.stderr, flush=True)
    rmw = rclpy.get_rmw_implementation_identifier()
    if is_content_filter_supported(session.node):
        try:
            return create_filtered_subscription(session.node, msg_type, topic, callback, qos,
                                                expression, parameters, raw=raw)
        except ContentFilterError as e:
            if args.filter_fallback != 'client' or e.rcl_error:
                reason = f'{rmw} rejected it: {e.rcl_error}' if e.rcl_error else str(e)
                raise FilterUnavailable(
                    f'cannot filter {topic}: content filter {expression!r} with parameters '
                    f'{parameters}: {reason}') from None
            unavailable = str(e)
    else:
        unavailable = f'{rmw} does not support content filtering'
        if args.filter_fallback != 'client':
            raise FilterUnavailable(
                f'cannot filter {topic}: content filter {expression!r}: {unavailable}. Refusing '
                'to subscribe unfiltered; pass --filter-fallback=client to evaluate the filter '
                'in this process instead')
    print(f'WARNING: {unavailable}; evaluating content filter {expression!r} in this process '
          '(--filter-fallback=client): every message crosses the network', file=sys.stderr,
          flush=True)
    if raw:
        from rclpy.serialization import deserialize_message

        def filtered(data):
            if client_filter.matches(deserialize_message(data, msg_type)):
                callback(data)
    else:
        def filtered(msg):
            if client_filter.matches(msg):
                callback(msg)
    return session.node.create_subscription(msg_type, topic, filtered, qos, raw=raw)


class _StdoutForUsOnly:
    """Keep file descriptor 1 for this tool's output, and send what C code prints to stderr.

    Fast DDS logs its errors (a filter it cannot parse, say) on stdout, which would mix them into
    the YAML that ``echo`` prints; from here on ``sys.stdout`` writes to a copy of the real stdout,
    and descriptor 1 is stderr.
    """

    def __enter__(self) -> None:
        sys.stdout.flush()
        self.saved_fd = os.dup(1)
        self.saved_stdout = sys.stdout
        sys.stdout = os.fdopen(os.dup(self.saved_fd), 'w', encoding='utf-8', errors='replace')
        os.dup2(2, 1)

    def __exit__(self, *_) -> None:
        try:
            sys.stdout.flush()
        except (BrokenPipeError, ValueError):
            pass
        finally:
            try:
                sys.stdout.close()
            except (BrokenPipeError, ValueError):
                pass
            os.dup2(self.saved_fd, 1)
            os.close(self.saved_fd)
            sys.stdout = self.saved_stdout


def _run(prog: str, body: Callable[[_Session], int]) -> int:
    """Run a command in a session; turn failures, Ctrl-C and a closed pipe into exit statuses."""
    with _StdoutForUsOnly():
        return _run_session(prog, body)


def _run_session(prog: str, body: Callable[[_Session], int]) -> int:
    from rclpy.executors import ExternalShutdownException

    session = None
    try:
        session = _Session()
        return body(session)
    except TopicToolError as e:
        print(f'{prog}: {e}', file=sys.stderr, flush=True)
        return e.exit_code
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    except BrokenPipeError:  # e.g. `| head`: stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return 0
    finally:
        if session is not None:
            session.close()


def run_echo(args: argparse.Namespace, prog: str = 'cft-action topic echo') -> int:
    """``cft-action topic echo``: print the messages that pass the filter, as YAML."""
    count = 1 if args.once else args.count
    truncate = None if args.full_length else args.truncate_length
    printed = 0

    def on_message(msg) -> None:
        nonlocal printed
        if count is not None and printed >= count:
            return
        text = message_to_yaml(msg, truncate_length=truncate, no_arr=args.no_arr,
                               no_str=args.no_str, flow_style=args.flow_style)
        sys.stdout.write(text + '---\n')
        sys.stdout.flush()
        printed += 1

    def body(session: _Session) -> int:
        deadline = _Deadline(args.timeout)
        topic, msg_type = _resolve(session, args.topic_name, args.message_type, deadline)
        qos = _choose_qos(session, topic, args)
        _subscribe(session, topic, msg_type, qos, on_message, args)
        while (count is None or printed < count) and not deadline.passed():
            session.spin_once(deadline.remaining(0.1))
        return 0

    return _run(prog, body)


class _RateWindow:
    """The intervals between the last ``window`` messages, as ``ros2 topic hz`` keeps them."""

    def __init__(self, window: int) -> None:
        self.intervals: deque[float] = deque(maxlen=window)
        self.last: Optional[float] = None
        self.fresh = False

    def tick(self, now: float) -> None:
        if self.last is not None:
            self.intervals.append(now - self.last)
            self.fresh = True
        self.last = now

    def report(self) -> Optional[str]:
        if not self.fresh or not self.intervals:
            return None
        self.fresh = False
        n = len(self.intervals)
        mean = sum(self.intervals) / n
        rate = 1.0 / mean if mean > 0 else 0.0
        std_dev = math.sqrt(sum((x - mean) ** 2 for x in self.intervals) / n)
        return (f'average rate: {rate:.3f}\n\tmin: {min(self.intervals):.3f}s max: '
                f'{max(self.intervals):.3f}s std dev: {std_dev:.5f}s window: {n}')


def _report_loop(session: _Session, deadline: _Deadline, report: Callable[[], Optional[str]],
                 period: float = 1.0) -> int:
    next_report = time.monotonic() + period
    while not deadline.passed():
        session.spin_once(min(deadline.remaining(0.1), next_report - time.monotonic()))
        if time.monotonic() >= next_report:
            next_report += period
            text = report()
            if text:
                print(text, flush=True)
    return 0


def run_hz(args: argparse.Namespace, prog: str = 'cft-action topic hz') -> int:
    """``cft-action topic hz``: print the rate of the messages that pass the filter."""
    window = _RateWindow(args.window)

    def body(session: _Session) -> int:
        deadline = _Deadline(args.timeout)
        topic, msg_type = _resolve(session, args.topic_name, args.message_type, deadline)
        qos = _choose_qos(session, topic, args)
        _subscribe(session, topic, msg_type, qos, lambda _: window.tick(time.monotonic()),
                   args)
        return _report_loop(session, deadline, window.report)

    return _run(prog, body)


def _bytes(value: float) -> str:
    for unit, size in (('MB', 1e6), ('KB', 1e3)):
        if value >= size:
            return f'{value / size:.2f} {unit}'
    return f'{value:.2f} B'


class _BandwidthWindow:
    """Arrival times and sizes of the last ``window`` messages, as ``ros2 topic bw`` keeps them."""

    def __init__(self, window: int) -> None:
        self.samples: deque[tuple[float, int]] = deque(maxlen=window)

    def add(self, data: bytes) -> None:
        self.samples.append((time.monotonic(), len(data)))

    def report(self) -> Optional[str]:
        if len(self.samples) < 2:
            return None
        sizes = [size for _, size in self.samples]
        elapsed = time.monotonic() - self.samples[0][0]
        rate = sum(sizes) / elapsed if elapsed > 0 else 0.0
        mean = sum(sizes) / len(sizes)
        return (f'{_bytes(rate)}/s from {len(sizes)} messages\n\tMessage size mean: '
                f'{_bytes(mean)} min: {_bytes(min(sizes))} max: {_bytes(max(sizes))}')


def run_bw(args: argparse.Namespace, prog: str = 'cft-action topic bw') -> int:
    """``cft-action topic bw``: print the bandwidth of the messages that pass the filter."""
    window = _BandwidthWindow(args.window)

    def body(session: _Session) -> int:
        deadline = _Deadline(args.timeout)
        topic, msg_type = _resolve(session, args.topic_name, args.message_type, deadline)
        qos = _choose_qos(session, topic, args)
        _subscribe(session, topic, msg_type, qos, window.add, args, raw=True)
        print(f'Subscribed to [{topic}]', flush=True)
        return _report_loop(session, deadline, window.report)

    return _run(prog, body)


# The short keys of rclpy.qos, listed here so that building the parser does not import rclpy.
_QOS_PROFILES = ('system_default', 'sensor_data', 'services_default', 'parameters',
                 'parameter_events', 'action_status_default', 'best_available')
_QOS_HISTORY = ('system_default', 'keep_last', 'keep_all')
_QOS_RELIABILITY = ('system_default', 'reliable', 'best_effort', 'best_available')
_QOS_DURABILITY = ('system_default', 'transient_local', 'volatile', 'best_available')


def add_qos_arguments(parser: argparse.ArgumentParser) -> None:
    """The QoS options of ``ros2 topic echo``, with its defaults."""
    group = parser.add_argument_group('quality of service')
    group.add_argument(
        '--qos-profile', choices=_QOS_PROFILES, default='sensor_data',
        help='Quality of service preset profile to subscribe with (default: sensor_data)')
    group.add_argument(
        '--qos-depth', metavar='N', type=_non_negative_int, default=None,
        help='Queue size setting to subscribe with (overrides depth value of --qos-profile '
             'option)')
    group.add_argument(
        '--qos-history', choices=_QOS_HISTORY, default=None,
        help='History of samples setting to subscribe with (overrides history value of '
             '--qos-profile option, default: keep_last)')
    group.add_argument(
        '--qos-reliability', choices=_QOS_RELIABILITY, default=None,
        help='Quality of service reliability setting to subscribe with (overrides reliability '
             'value of --qos-profile option, default: Automatically match existing publishers)')
    group.add_argument(
        '--qos-durability', choices=_QOS_DURABILITY, default=None,
        help='Quality of service durability setting to subscribe with (overrides durability '
             'value of --qos-profile option, default: Automatically match existing publishers)')


def add_filter_arguments(parser: argparse.ArgumentParser) -> None:
    """``--filter``, ``--params`` and ``--filter-fallback``."""
    group = parser.add_argument_group(
        'content filter',
        'The middleware drops the messages that do not match, before they cross the network.\n'
        'If the filter cannot be applied the command exits with status 2 and the reason, and\n'
        'prints no message.')
    group.add_argument(
        '--filter', metavar='EXPR', default=None,
        help="DDS-SQL expression over the message fields, e.g. \"data > %%0\" or \"pose.position.x "
             "< 1.5 AND header.frame_id = 'map'\". Arrays are indexed: \"values[0] = 3\". "
             'Operators: = <> < <= > >= LIKE (%% and _) MATCH BETWEEN AND OR NOT and parentheses; '
             'AND and OR have the same precedence (use parentheses)')
    group.add_argument(
        '--params', metavar='VALUE', nargs='+', action='extend', default=None,
        help="Values of %%0, %%1, ... in --filter. A bare string is quoted for you: hello is sent "
             "as 'hello'; give '30' (quoted) to compare a string with a number. Put this option "
             'after the positional arguments')
    group.add_argument(
        '--filter-fallback', choices=('none', 'client'), default='none',
        help='What to do when the rmw implementation cannot filter: none (default) exits with '
             'status 2; client evaluates the expression in this process, so every message '
             'crosses the network')


def _non_negative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError('value must be non-negative integer')
    return value


def _positive_int(text: str) -> int:
    value = _non_negative_int(text)
    if value == 0:
        raise argparse.ArgumentTypeError('value must be a positive integer')
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not value > 0 or math.isinf(value):
        raise argparse.ArgumentTypeError('value must be a positive number')
    return value


def add_echo_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('topic_name', help="Name of the ROS topic to listen to (e.g. '/chatter')")
    parser.add_argument(
        'message_type', nargs='?',
        help="Type of the ROS message (e.g. 'std_msgs/msg/String'); found in the graph if omitted")
    add_filter_arguments(parser)
    add_qos_arguments(parser)
    parser.add_argument(
        '--once', action='store_true', help='Print the first message received and then exit.')
    parser.add_argument(
        '--count', metavar='N', type=_positive_int, default=None,
        help='Print N messages and then exit.')
    parser.add_argument(
        '--timeout', metavar='S', type=_positive_float, default=None,
        help='Exit after S seconds, whether or not messages arrived (status 0).')
    parser.add_argument(
        '--full-length', '-f', action='store_true',
        help='Output all elements for arrays, bytes, and string with a length > '
             "'--truncate-length', by default they are truncated after '--truncate-length' "
             "elements with '...'")
    parser.add_argument(
        '--truncate-length', '-l', type=_non_negative_int, default=DEFAULT_TRUNCATE_LENGTH,
        help=f'The length to truncate arrays, bytes, and string to (default: '
             f'{DEFAULT_TRUNCATE_LENGTH})')
    parser.add_argument(
        '--no-arr', action='store_true', help="Don't print array fields of messages")
    parser.add_argument(
        '--no-str', action='store_true', help="Don't print string fields of messages")
    parser.add_argument(
        '--flow-style', action='store_true', help='Print collections in the flow style')


def add_rate_arguments(parser: argparse.ArgumentParser, *, default_window: int, what: str) -> None:
    parser.add_argument('topic_name', help=f'Name of the ROS topic to {what}')
    parser.add_argument(
        'message_type', nargs='?',
        help="Type of the ROS message (e.g. 'std_msgs/msg/String'); found in the graph if omitted")
    add_filter_arguments(parser)
    add_qos_arguments(parser)
    parser.add_argument(
        '--window', '-w', metavar='WINDOW', type=_positive_int, default=default_window,
        help=f'window size, in # of messages, for calculating rate (default: {default_window})')
    parser.add_argument(
        '--timeout', metavar='S', type=_positive_float, default=None,
        help='Exit after S seconds (status 0).')


