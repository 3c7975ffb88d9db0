# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""``cft-action topic echo``: print the messages of a topic that pass its filters, as
``ros2 topic echo`` (Jazzy) prints them.

The content filter is applied by the middleware; then, as in ros2cli, ``--field`` selects a part
of each message and ``--filter`` (Python, on ``m``) is evaluated on that part.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any, Callable, Optional

import yaml

from cft_action.topics import topic_api
from cft_action.verb import examples
from cft_action.topics.message_yaml import message_to_csv, message_to_yaml

HELP = 'Output messages from a topic'

DESCRIPTION = """\
Output, as YAML, the messages of a topic that pass the content filter and --filter.

The content filter (--content-filter, DDS-SQL) is applied by the middleware: messages that do not
match never reach this process. If it cannot be applied (a syntax error, an unknown field, an rmw
implementation without content filtering), the command exits with status 2 and the reason, and
prints no message. --filter is ros2 topic echo's: a Python expression on the message m, evaluated
in this process on what the content filter let through."""

EPILOG = examples(
    'cft-action topic echo /chatter std_msgs/msg/String --content-filter "data = %0" '
    '--content-filter-params hello',
    'cft-action topic echo /chatter std_msgs/msg/String --filter "m.data == \'hello\'"',
    'cft-action topic echo /weather --content-filter "temperature > %0" '
    '--content-filter-params 30.0',
    'cft-action topic echo /diagnostics --content-filter "status[0].level >= 2" --once',
    'cft-action topic echo /odom --content-filter "pose.pose.position.x BETWEEN -1.0 AND 1.0" '
    '--field pose.pose.position --csv',
    'cft-action topic echo /camera/info --poll 1',
    'cft-action topic echo /odom --max-rate 2')

DEFAULT_TRUNCATE_LENGTH = 128


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """ros2cli's ``echo`` arguments, the content filter and ``--count``."""
    topic_api.add_topic_arguments(
        parser, "listen to (e.g. '/chatter')",
        'Exit after S seconds, whether or not messages arrived (status 0).')
    parser.add_argument(
        '--csv', action='store_true',
        help='Output all recursive fields separated by commas (e.g. for plotting). If '
             '--include-message-info is also passed, the following fields are prepended: '
             'source_timestamp, received_timestamp, publication_sequence_number, '
             'reception_sequence_number.')
    parser.add_argument(
        '--field', type=str, default=None,
        help="Echo a selected field of a message. Use '.' to select sub-fields. For example, to "
             'echo the position field of a nav_msgs/msg/Odometry message: '
             "'--field pose.pose.position'")
    parser.add_argument(
        '--full-length', '-f', action='store_true',
        help='Output all elements for arrays, bytes, and string with a length > '
             "'--truncate-length', by default they are truncated after '--truncate-length' "
             "elements with '...'")
    parser.add_argument(
        '--truncate-length', '-l', type=topic_api.non_negative_int,
        default=DEFAULT_TRUNCATE_LENGTH,
        help=f'The length to truncate arrays, bytes, and string to (default: '
             f'{DEFAULT_TRUNCATE_LENGTH})')
    parser.add_argument(
        '--no-arr', action='store_true', help="Don't print array fields of messages")
    parser.add_argument(
        '--no-str', action='store_true', help="Don't print string fields of messages")
    parser.add_argument(
        '--flow-style', action='store_true',
        help='Print collections in the flow style (not available with csv format)')
    parser.add_argument(
        '--no-lost-messages', action='store_true',
        help="Accepted for ros2 topic echo's command lines; lost messages are never reported "
             '(Fast DDS counts the samples that a content filter drops as lost)')
    parser.add_argument(
        '--raw', action='store_true', help='Echo the raw binary representation')
    topic_api.add_python_filter_argument(
        parser, 'Python expression to filter messages that are printed. Expression can use '
                'Python builtins as well as m (the message, or the --field). Evaluated in '
                'this process, after the content filter')
    parser.add_argument(
        '--once', action='store_true', help='Print the first message received and then exit.')
    parser.add_argument(
        '--count', metavar='N', type=topic_api.positive_int, default=None,
        help='Print N messages and then exit.')
    parser.add_argument(
        '--include-message-info', '-i', action='store_true',
        help='Shows the associated message info.')
    parser.add_argument(
        '--poll', metavar='N', type=topic_api.positive_int, default=None,
        help='Print the next N messages of each publisher, then exit: the others are dropped by '
             'the publisher under cft-action guard, else by this process\'s DDS reader')


def _field_path(args: argparse.Namespace, parser: argparse.ArgumentParser) -> list[str]:
    if args.field is None:
        return []
    path = [part for part in args.field.split('.') if part]
    if not path:
        parser.error(f"invalid --field value '{args.field}'")
    return path


def main(args: argparse.Namespace, parser: argparse.ArgumentParser, prog: str) -> int:
    """Print the messages that pass the filters; exit after ``--once``, ``--count`` or
    ``--timeout``."""
    if args.once and args.count is not None:
        parser.error('--once and --count cannot be combined')
    if args.raw and (args.field is not None or args.csv):
        parser.error('--raw cannot be combined with --field or --csv')
    field = _field_path(args, parser)
    count = 1 if args.once else args.count
    truncate = None if args.full_length else args.truncate_length
    printed = 0
    keep: Optional[Callable[[Any], bool]] = None

    def on_message(msg: Any, info: Any) -> None:
        nonlocal printed
        if count is not None and printed >= count:
            return
        part = msg
        for name in field:
            try:
                part = getattr(part, name)
            except AttributeError as e:
                raise topic_api.TopicToolError(f"invalid field '{'.'.join(field)}': {e}") from None
        if keep is not None and not keep(part):
            return
        sys.stdout.write(_format(part, info, args, truncate))
        sys.stdout.flush()
        printed += 1

    def body(session: topic_api.Session) -> int:
        nonlocal keep
        keep = topic_api.python_filter(args.filter_expr)
        topic, deadline = topic_api.start(session, args, on_message, raw=args.raw)
        while (count is None or printed < count) and not deadline.passed():
            if args.poll is not None and printed >= args.poll * max(
                    1, session.node.count_publishers(topic)):
                break  # every publisher's N
            session.spin_once(deadline.remaining(0.1))
        return 0

    return topic_api.run(prog, body)


def _format(part: Any, info: Any, args: argparse.Namespace, truncate) -> str:
    """One message (or field) as ros2cli prints it: raw, CSV or YAML, then ``---`` but for CSV."""
    if not hasattr(part, '__slots__'):  # raw bytes, or a field that is not a message
        header = f'---Got new message, message info:---\n{info}\n---Message data:---\n' \
            if args.include_message_info else ''
        return f'{header}{part}\n---\n'
    if args.csv:
        text = message_to_csv(part, truncate_length=truncate, no_arr=args.no_arr,
                              no_str=args.no_str)
        if args.include_message_info:
            text = ','.join(str(value) for value in info.values()) + ',' + text
        return text + '\n'
    header = yaml.safe_dump(dict(info)) + '---\n' if args.include_message_info else ''
    return header + message_to_yaml(part, truncate_length=truncate, no_arr=args.no_arr,
                                    no_str=args.no_str, flow_style=args.flow_style) + '---\n'
