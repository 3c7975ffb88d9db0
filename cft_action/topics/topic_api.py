# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""What the ``cft-action topic`` verbs share, as ``ros2topic.api`` for ``ros2 topic``.

The verbs themselves are :mod:`cft_action.verb.echo`, :mod:`cft_action.verb.hz` and
:mod:`cft_action.verb.bw`; this module has their common arguments, the session (an rclpy context,
a node and an executor), the type lookup, ros2cli's choice of QoS, the subscription with its content
filter, ros2cli's Python ``--filter`` and the handling of output and exit statuses. rclpy is
imported only when a command runs, so that ``--help`` stays fast.

Two filters, in ros2cli's terms:

- ``--content-filter EXPR --content-filter-params VALUE ...`` (the names of ros2cli#1213) is a
  DDS-SQL expression applied by the middleware: messages that do not match never reach this
  process. If it cannot be applied, the command exits with :data:`EXIT_FILTER` and the reason, and
  prints no message: there is no silent fallback to unfiltered messages.
  ``--content-filter-fallback=client`` is the explicit opt-in to evaluating the expression in this
  process when the rmw implementation has no content filtering. Filters are checked against
  :func:`cft_action.topics.message_types.message_schema`, the kinds of a message's fields as Fast
  DDS sees them.
- ``--filter EXPR`` is Jazzy's ``ros2 topic echo|hz`` option: a Python expression on the message
  ``m``, evaluated in this process on the messages that passed the content filter.
"""

from __future__ import annotations

import argparse
import builtins
import copy
import importlib
import math
import os
import sys
import time
from typing import Any, Callable, Optional

from cft_action.topics import sql
from cft_action.errors import CftActionError
from cft_action.topics.message_types import is_message, message_schema

__all__ = [
    'EXIT_ERROR', 'EXIT_FILTER', 'Deadline', 'FilterUnavailable', 'Session', 'TopicToolError',
    'add_content_filter_arguments', 'add_python_filter_argument', 'add_qos_arguments',
    'add_topic_arguments', 'choose_qos',
    'get_message_class', 'python_filter', 'report_loop', 'resolve_topic', 'run', 'start',
    'subscribe',
]

#: Exit status when the filter cannot be applied (and for command-line usage errors, as argparse).
EXIT_FILTER = 2
#: Exit status of any other failure: an unknown type, a topic that never appears.
EXIT_ERROR = 1


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

# --- the session ----------------------------------------------------------------------------------

class Session:
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


class Deadline:
    def __init__(self, seconds: Optional[float]) -> None:
        self.end = None if seconds is None else time.monotonic() + seconds

    def remaining(self, cap: float = 0.1) -> float:
        if self.end is None:
            return cap
        return min(cap, self.end - time.monotonic())

    def passed(self) -> bool:
        return self.end is not None and time.monotonic() >= self.end


def resolve_topic(session: Session, topic: str, type_name: Optional[str], deadline: Deadline):
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


def choose_qos(session: Session, topic: str, args: argparse.Namespace):
    """ros2cli's choice: a preset, made reliable or transient-local when every publisher is."""
    from rclpy.qos import (QoSDurabilityPolicy, QoSHistoryPolicy, QoSPresetProfiles,
                           QoSReliabilityPolicy)

    profile = copy.copy(QoSPresetProfiles.get_from_short_key(args.qos_profile))
    publishers = session.node.get_publishers_info_by_topic(topic)

    def policy(name: str, override: Optional[str], kind, when_all, otherwise):
        """``override``, or ``when_all`` if every publisher offers it, else ``otherwise``."""
        if override is not None:
            return kind.get_from_short_key(override)
        if not publishers:
            return getattr(profile, name)
        offered = all(getattr(p.qos_profile, name) == when_all for p in publishers)
        return when_all if offered else otherwise

    profile.reliability = policy('reliability', args.qos_reliability, QoSReliabilityPolicy,
                                 QoSReliabilityPolicy.RELIABLE, QoSReliabilityPolicy.BEST_EFFORT)
    profile.durability = policy('durability', args.qos_durability, QoSDurabilityPolicy,
                                QoSDurabilityPolicy.TRANSIENT_LOCAL, QoSDurabilityPolicy.VOLATILE)
    if args.qos_history is not None:
        profile.history = QoSHistoryPolicy.get_from_short_key(args.qos_history)
    if args.qos_depth is not None:
        profile.depth = args.qos_depth
    return profile


def subscribe(session: Session, topic: str, msg_type, qos, callback: Callable[..., None],
              args: argparse.Namespace, *, raw: bool = False):
    """Subscribe with the content filter of ``args`` applied by the middleware, or raise
    FilterUnavailable.

    ``callback`` takes the message and its message info, as an rclpy subscription's callback with
    two parameters. The expression is checked first by :mod:`cft_action.topics.sql`, so that a bad
    one is reported with its reason and a LIKE pattern that would abort Fast DDS never reaches it.
    With
    ``--content-filter-fallback=client`` and an rmw implementation without content filtering, the
    expression is evaluated here on each message instead, and a warning says so.
    """
    import rclpy
    from cft_action.topics.filters import dds_literals
    from cft_action.errors import InvalidArgumentError
    from cft_action.topics.subscription import (ContentFilterError, create_filtered_subscription,
                                                is_content_filter_supported)

    # Fast DDS rejects an expression that starts or ends with a space, which a shell makes easy
    expression = None if args.content_filter is None else args.content_filter.strip()
    rate = {'max_rate': args.max_rate, 'poll': getattr(args, 'poll', None)}
    if rate['max_rate'] is not None or rate['poll'] is not None:
        if expression is not None:
            raise FilterUnavailable(
                '--max-rate and --poll take no --content-filter: a subscription has one filter, '
                'and the rate filter is not DDS-SQL')
        try:
            return create_filtered_subscription(session.node, msg_type, topic, callback, qos,
                                                raw=raw, **rate)
        except (ContentFilterError, InvalidArgumentError) as e:
            raise FilterUnavailable(f'cannot rate-limit or poll {topic}: {e}') from None
    if expression is None:
        if args.content_filter_params:
            raise FilterUnavailable('--content-filter-params needs --content-filter')
        return session.node.create_subscription(msg_type, topic, callback, qos, raw=raw)
    try:
        parameters = dds_literals(args.content_filter_params or ())
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
            if args.content_filter_fallback != 'client' or e.rcl_error:
                reason = f'{rmw} rejected it: {e.rcl_error}' if e.rcl_error else str(e)
                raise FilterUnavailable(
                    f'cannot filter {topic}: content filter {expression!r} with parameters '
                    f'{parameters}: {reason}') from None
            unavailable = str(e)
    else:
        unavailable = f'{rmw} does not support content filtering'
        if args.content_filter_fallback != 'client':
            raise FilterUnavailable(
                f'cannot filter {topic}: content filter {expression!r}: {unavailable}. Refusing '
                'to subscribe unfiltered; pass --content-filter-fallback=client to evaluate the '
                'filter in this process instead')
    print(f'WARNING: {unavailable}; evaluating content filter {expression!r} in this process '
          '(--content-filter-fallback=client): every message crosses the network', file=sys.stderr,
          flush=True)
    from rclpy.serialization import deserialize_message

    def filtered(msg, info) -> None:
        if client_filter.matches(deserialize_message(msg, msg_type) if raw else msg):
            callback(msg, info)

    # rclpy passes the message info to a callback with two parameters; its type hint has one
    two_parameters: Callable[..., None] = filtered
    return session.node.create_subscription(msg_type, topic, two_parameters, qos, raw=raw)

def python_filter(expression: Optional[str]) -> Optional[Callable[[Any], bool]]:
    """ros2cli's ``--filter``: a function of the message ``m`` that tells whether to keep it, or
    None without an expression.

    The expression is Python, evaluated with the builtins and ``m`` (``m.data == 'hello'``), as
    ``ros2 topic echo`` and ``hz`` evaluate it; ``m`` is a global of the evaluation, so that
    comprehensions see it too. It is compiled here, so that a syntax error ends the command before
    it subscribes (:class:`FilterUnavailable`); an exception while evaluating it on a message ends
    the command with :data:`EXIT_ERROR` and the exception.
    """
    if expression is None:
        return None
    try:
        code = compile(expression, '<--filter>', 'eval')
    except SyntaxError as e:
        raise FilterUnavailable(
            f'--filter {expression!r} is not a Python expression ({e.msg}). --filter takes a '
            "Python expression on the message m, as ros2 topic echo's, e.g. \"m.data == "
            "'hello'\"; a DDS-SQL expression goes to --content-filter") from None

    def keep(m: Any) -> bool:
        try:
            return bool(eval(code, {'__builtins__': builtins, 'm': m}))
        except Exception as e:  # noqa: BLE001 - the user's expression can raise anything
            raise TopicToolError(f'--filter {expression!r} failed on a message: '
                                 f'{type(e).__name__}: {e}') from None

    return keep


def start(session: Session, args: argparse.Namespace, callback: Callable[..., None], *,
          raw: bool = False) -> tuple[str, Deadline]:
    """Resolve ``args.topic_name`` and subscribe ``callback(msg, info)`` to it, with the QoS and
    the content filter of ``args``; return the topic's full name and the deadline of ``--timeout``.
    """
    deadline = Deadline(args.timeout)
    topic, msg_type = resolve_topic(session, args.topic_name, args.message_type, deadline)
    qos = choose_qos(session, topic, args)
    subscribe(session, topic, msg_type, qos, callback, args, raw=raw)
    return topic, deadline


def report_loop(session: Session, deadline: Deadline, report: Callable[[], Optional[str]],
                period: float = 1.0) -> int:
    """Spin until the deadline, printing ``report()`` every ``period`` seconds when it has one."""
    next_report = time.monotonic() + period
    while not deadline.passed():
        session.spin_once(min(deadline.remaining(0.1), next_report - time.monotonic()))
        if time.monotonic() >= next_report:
            next_report += period
            text = report()
            if text:
                print(text, flush=True)
    return 0


# --- output and exit statuses ---------------------------------------------------------------------

class StdoutForUsOnly:
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


def run(prog: str, body: Callable[[Session], int]) -> int:
    """Run a command in a session; turn failures, Ctrl-C and a closed pipe into exit statuses."""
    with StdoutForUsOnly():
        return _run_session(prog, body)


def _run_session(prog: str, body: Callable[[Session], int]) -> int:
    from rclpy.executors import ExternalShutdownException

    session = None
    try:
        session = Session()
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

# --- arguments ------------------------------------------------------------------------------------

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
        '--qos-depth', metavar='N', type=non_negative_int, default=None,
        help='Queue size setting to subscribe with (overrides depth value of --qos-profile '
             'option)')
    matched = 'Automatically match existing publishers'
    for policy, choices, what, default in (
            ('history', _QOS_HISTORY, 'History of samples', 'keep_last'),
            ('reliability', _QOS_RELIABILITY, 'Quality of service reliability', matched),
            ('durability', _QOS_DURABILITY, 'Quality of service durability', matched)):
        group.add_argument(
            f'--qos-{policy}', choices=choices, default=None,
            help=f'{what} setting to subscribe with (overrides {policy} value of --qos-profile '
                 f'option, default: {default})')


def non_negative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError('value must be non-negative integer')
    return value


def positive_int(text: str) -> int:
    value = non_negative_int(text)
    if value == 0:
        raise argparse.ArgumentTypeError('value must be a positive integer')
    return value


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not value > 0 or math.isinf(value):
        raise argparse.ArgumentTypeError('value must be a positive number')
    return value


def add_topic_arguments(parser: argparse.ArgumentParser, what: str,
                        timeout_help: str = 'Exit after S seconds (status 0).', *,
                        window: Optional[int] = None) -> None:
    """What every topic verb has: the positional ``topic_name`` and optional ``message_type``, the
    content filter, the QoS and ``--timeout``; and ros2cli's ``--window/-w`` of ``hz`` and ``bw``
    with its default, if ``window`` is given."""
    parser.add_argument('topic_name', help=f'Name of the ROS topic to {what}')
    parser.add_argument(
        'message_type', nargs='?',
        help="Type of the ROS message (e.g. 'std_msgs/msg/String'); found in the graph if omitted")
    add_content_filter_arguments(parser)
    add_qos_arguments(parser)
    parser.add_argument('--timeout', metavar='S', type=positive_float, default=None,
                        help=timeout_help)
    if window is not None:
        parser.add_argument(
            '--window', '-w', metavar='WINDOW', type=positive_int, default=window,
            help=f'window size, in # of messages, for calculating rate (default: {window})')


def add_content_filter_arguments(parser: argparse.ArgumentParser) -> None:
    """``--content-filter``, ``--content-filter-params`` and ``--content-filter-fallback``."""
    group = parser.add_argument_group(
        'content filter',
        'The middleware drops the messages that do not match, before they cross the network.\n'
        'If the filter cannot be applied the command exits with status 2 and the reason, and\n'
        'prints no message.')
    group.add_argument(
        '--content-filter', metavar='EXPR', default=None,
        help="DDS-SQL expression over the message fields, e.g. \"data > %%0\" or \"pose.position.x "
             "< 1.5 AND header.frame_id = 'map'\". Arrays are indexed: \"values[0] = 3\". "
             'Operators: = <> < <= > >= LIKE (%% and _) MATCH BETWEEN AND OR NOT and parentheses; '
             'AND and OR have the same precedence (use parentheses)')
    group.add_argument(
        '--content-filter-params', metavar='VALUE', nargs='+', action='extend', default=None,
        help="Values of %%0, %%1, ... in --content-filter. A bare string is quoted for you: hello "
             "is sent as 'hello'; give '30' (quoted) to compare a string with a number. Put this "
             'option after the positional arguments')
    group.add_argument(
        '--content-filter-fallback', choices=('none', 'client'), default='none',
        help='What to do when the rmw implementation cannot filter: none (default) exits with '
             'status 2; client evaluates the expression in this process, so every message '
             'crosses the network')
    group.add_argument(
        '--max-rate', metavar='HZ', type=positive_float, default=None,
        help='At most HZ messages a second from each publisher, the first after each 1/HZ s: a '
             'publisher under cft-action guard drops the others before they cross the network, '
             "else this process's DDS reader does (not with --content-filter)")


def add_python_filter_argument(parser: argparse.ArgumentParser, help_text: str) -> None:
    """ros2cli's ``--filter EXPR`` (``dest='filter_expr'``), a Python expression on ``m``."""
    parser.add_argument('--filter', dest='filter_expr', metavar='EXPR', default=None,
                        help=help_text)
