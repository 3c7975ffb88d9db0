# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""``cft-action guard``: run a command (normally an action server) with the server guard
preloaded."""

from __future__ import annotations

import argparse
import os
import sys

from cft_action.verb import examples

HELP = 'Run a command with the server guard preloaded'

DESCRIPTION = """\
Run a command (normally an action server) with the cft_action server guard preloaded.

With Fast DDS 2.14 and 3.2, clients that change their content filters, or filtered readers that
go away, can crash the process that publishes to them. The guard (an LD_PRELOAD library) serializes
each writer's publish with the discovery updates of its filters. Preload it into the server;
clients need nothing. On a Fast DDS version it does not know, it prints one line and stays out of
the way. Set CFT_GUARD_DEBUG=1 to see what it does."""

EPILOG = examples('cft-action guard -- python my_action_server.py',
                  'LD_PRELOAD=$(cft-action guard --print-path) ros2 run my_pkg my_server')


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``--print-path`` and the command to run."""
    parser.add_argument(
        '--print-path', action='store_true',
        help='Print the path of the guard library (for LD_PRELOAD) and exit')
    parser.add_argument(
        'command', nargs=argparse.REMAINDER, metavar='-- command ...',
        help='The command to run with the guard preloaded, e.g. '
             '`-- python my_action_server.py`; it replaces this process')


def main(args: argparse.Namespace, parser: argparse.ArgumentParser, prog: str) -> int:
    """Print the library's path, or replace this process by the command with the guard."""
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
            parser.error(f'a command to run is required, e.g. `{prog} -- python '
                         'my_action_server.py`')
        env = guard.environment()
    except guard.GuardUnavailable as e:
        print(f'{prog}: {e}', file=sys.stderr)
        return 1
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        os.execvpe(command[0], command, env)
    except FileNotFoundError:
        print(f'{prog}: command not found: {command[0]}', file=sys.stderr)
        return 127
    except OSError as e:
        print(f'{prog}: cannot run {command[0]}: {e}', file=sys.stderr)
        return 126
    return 0  # not reached: execvpe replaced this process
