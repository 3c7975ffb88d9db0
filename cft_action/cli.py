# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The ``cft-action`` command line, in the style of ros2cli.

    cft-action guard -- python my_action_server.py   # run a server with the guard preloaded
    cft-action guard --print-path                     # the library to put in LD_PRELOAD yourself

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


# --- the command table ----------------------------------------------------------------------------

_Runner = Callable[[argparse.Namespace, argparse.ArgumentParser], int]

# name: (one-line help, full description, epilog, add_arguments, run)
_COMMANDS: dict[str, tuple[str, str, str, Callable[[argparse.ArgumentParser], None], _Runner]] = {
    'guard': ('Run a command with the server guard preloaded', _GUARD_DESCRIPTION, _GUARD_EPILOG,
              _add_guard_arguments, _run_guard),
}


def _build_parser() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    parser = argparse.ArgumentParser(
        prog=_PROG,
        description=f'{_PROG} is a command-line tool for content-filtered ROS 2 action feedback.',
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
