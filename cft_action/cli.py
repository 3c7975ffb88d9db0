# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The ``cft-action`` command line, in the style of ros2cli.

    cft-action guard -- python my_action_server.py   # run a server with the guard preloaded
    cft-action guard --print-path                     # the library to put in LD_PRELOAD yourself
    cft-action topic echo /weather --filter "temperature > %0" --params 30.0
    cft-action topic hz /chatter std_msgs/msg/String --filter "data LIKE 'hello%'"

Each command is a sub-parser registered in :data:`_COMMANDS`; a new one (e.g. ``topic``) adds a
``(name, help, add_arguments, run)`` entry there.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Callable, Optional, Sequence

_PROG = 'cft-action'


# --- cft-action guard -----------------------------------------------------------------------------

def _add_guard_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        '--print-path', action='store_true',
        help='Print the path of the guard library (for LD_PRELOAD) and exit')
    parser.add_argument(
        'command', nargs=argparse.REMAINDER, metavar='-- command ...',
        help='The command to run with the guard preloaded, e.g. '
             '`-- python my_action_server.py`; it replaces this process')


def _run_guard(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from cft_action import guard

    command = list(args.command)
    if command and command[0] == '--':
        command = command[1:]
    try:
        if args.print_path:
            if command:
                parser.error('--print-path takes no command')
            print(guard.library_path())
            return 0
        if not command:
            parser.error('a command to run is required, e.g. '
                         f'`{_PROG} guard -- python my_action_server.py`')
        env = guard.environment()
    except guard.GuardUnavailable as e:
        print(f'{_PROG} guard: {e}', file=sys.stderr)
        return 1
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        os.execvpe(command[0], command, env)
    except FileNotFoundError:
        print(f'{_PROG} guard: command not found: {command[0]}', file=sys.stderr)
        return 127
    except OSError as e:
        print(f'{_PROG} guard: cannot run {command[0]}: {e}', file=sys.stderr)
        return 126
    return 0  # not reached: execvpe replaced this process


_GUARD_DESCRIPTION = """\
Run a command (normally an action server) with the cft_action server guard preloaded.

With Fast DDS 2.14 and 3.2, clients that change their content filters, or filtered readers that
go away, can crash the process that publishes to them. The guard (an LD_PRELOAD library) serializes
each writer's publish with the discovery updates of its filters. Preload it into the server;
clients need nothing. On a Fast DDS version it does not know, it prints one line and stays out of
the way. Set CFT_GUARD_DEBUG=1 to see what it does."""

_GUARD_EPILOG = f"""\
examples:
  {_PROG} guard -- python my_action_server.py
  LD_PRELOAD=$({_PROG} guard --print-path) ros2 run my_pkg my_server"""


# --- cft-action topic echo|hz|bw -----------------------------------------------------------------

# verb: (one-line help, description, epilog). The verbs' options and code live in
# cft_action.topic_tools, which imports rclpy only when a command runs: help stays fast.
_TOPIC_VERBS = {
    'bw': ('Display bandwidth used by topic', """\
Display the bandwidth used by the messages of a topic that pass the content filter.

The filter is applied by the middleware: messages that do not match never reach this process.""",
           f"""\
examples:
  {_PROG} topic bw /strings std_msgs/msg/String --filter "data = %0" --params world
  {_PROG} topic bw /scan --filter "ranges[0] < 0.5" --window 50"""),
    'echo': ('Output messages from a topic', """\
Output, as YAML, the messages of a topic that pass the content filter.

The filter is applied by the middleware: messages that do not match never reach this process. If
it cannot be applied (a syntax error, an unknown field, an rmw implementation without content
filtering), the command exits with status 2 and the reason, and prints no message.""",
             f"""\
examples:
  {_PROG} topic echo /weather --filter "temperature > %0" --params 30.0
  {_PROG} topic echo /topic std_msgs/msg/String --filter "data = %0" --params hello
  {_PROG} topic echo /diagnostics --filter "status[0].level >= 2" --once
  {_PROG} topic echo /odom --filter "pose.pose.position.x BETWEEN -1.0 AND 1.0" --count 10"""),
    'hz': ('Print the average publishing rate to screen', """\
Print the average rate, and the minimum, maximum and standard deviation of the intervals, of the
messages of a topic that pass the content filter, once a second.

The filter is applied by the middleware: messages that do not match never reach this process.""",
           f"""\
examples:
  {_PROG} topic hz /strings std_msgs/msg/String --filter "data = %0" --params world
  {_PROG} topic hz /chatter --filter "data LIKE 'Hello%'" --window 100"""),
}


def _add_topic_arguments(parser: argparse.ArgumentParser) -> None:
    from cft_action import topic_tools

    adders = {
        'echo': topic_tools.add_echo_arguments,
        'hz': lambda p: topic_tools.add_rate_arguments(p, default_window=10000,
                                                       what='listen to (e.g. \'/chatter\')'),
        'bw': lambda p: topic_tools.add_rate_arguments(p, default_window=100,
                                                       what='monitor for bandwidth utilization'),
    }
    verbs = parser.add_subparsers(title='Commands', dest='_verb', metavar='<command>')
    for verb, (help_text, description, epilog) in sorted(_TOPIC_VERBS.items()):
        sub = verbs.add_parser(verb, help=help_text, description=description, epilog=epilog,
                               formatter_class=argparse.RawDescriptionHelpFormatter)
        adders[verb](sub)
        sub.set_defaults(_verb_parser=sub)


def _run_topic(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from cft_action import topic_tools

    if not args._verb:
        parser.print_help()
        return 0
    if args._verb == 'echo' and args.once and args.count is not None:
        args._verb_parser.error('--once and --count cannot be combined')
    run = {'echo': topic_tools.run_echo, 'hz': topic_tools.run_hz,
           'bw': topic_tools.run_bw}[args._verb]
    return run(args, f'{_PROG} topic {args._verb}')


_TOPIC_DESCRIPTION = """\
Various topic related sub-commands, with DDS content filters applied by the middleware.

--filter takes a DDS-SQL expression over the message fields; the middleware drops the messages that
do not match before they cross the network. There is no silent fallback: a filter that cannot be
applied ends the command with status 2 and the reason."""

_TOPIC_EPILOG = f"""\
examples:
  {_PROG} topic echo /weather --filter "temperature > %0" --params 30.0
  {_PROG} topic hz /chatter std_msgs/msg/String --filter "data = %0" --params hello

  Call `{_PROG} topic <command> -h` for more detailed usage."""


# --- the command table ----------------------------------------------------------------------------

_Runner = Callable[[argparse.Namespace, argparse.ArgumentParser], int]

# name: (one-line help, full description, epilog, add_arguments, run)
_COMMANDS: dict[str, tuple[str, str, str, Callable[[argparse.ArgumentParser], None], _Runner]] = {
    'guard': ('Run a command with the server guard preloaded', _GUARD_DESCRIPTION, _GUARD_EPILOG,
              _add_guard_arguments, _run_guard),
    'topic': ('Various topic related sub-commands, with content filters', _TOPIC_DESCRIPTION,
              _TOPIC_EPILOG, _add_topic_arguments, _run_topic),
}


def _build_parser() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    parser = argparse.ArgumentParser(
        prog=_PROG,
        description=f'{_PROG} is a command-line tool for content-filtered ROS 2 action feedback '
                    'and topics.',
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=f'  Call `{_PROG} <command> -h` for more detailed usage.')
    subparsers = parser.add_subparsers(
        title='Commands', dest='_command', metavar='<command>')
    parsers = {}
    for name, (help_text, description, epilog, add_arguments, _) in _COMMANDS.items():
        sub = subparsers.add_parser(
            name, help=help_text, description=description, epilog=epilog,
            formatter_class=argparse.RawDescriptionHelpFormatter)
        add_arguments(sub)
        parsers[name] = sub
    return parser, parsers


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of the ``cft-action`` console script; returns the exit status."""
    parser, parsers = _build_parser()
    args = parser.parse_args(argv)
    if not args._command:
        parser.print_help()
        return 0
    run = _COMMANDS[args._command][4]
    return run(args, parsers[args._command])


if __name__ == '__main__':
    sys.exit(main())
