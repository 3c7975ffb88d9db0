# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The ``cft-action`` command line, in the style of ros2cli.

    cft-action guard -- python my_action_server.py   # run a server with the guard preloaded
    cft-action guard --print-path                     # the library to put in LD_PRELOAD yourself
    cft-action topic echo /weather --content-filter "temperature > %0" --content-filter-params 30.0
    cft-action topic hz /chatter std_msgs/msg/String --filter "m.data.startswith('hello')"

Each verb is a module of :mod:`cft_action.verb` with its help texts, ``add_arguments`` and
``main``; this module only builds the parsers from them and dispatches.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from types import ModuleType
from typing import Optional, Sequence

from cft_action.verb import TOPIC_VERBS

_PROG = 'cft-action'

_TOPIC_HELP = 'Various topic related sub-commands, with content filters'

_TOPIC_DESCRIPTION = """\
Various topic related sub-commands, with DDS content filters applied by the middleware.

--content-filter takes a DDS-SQL expression over the message fields; the middleware drops the
messages that do not match before they cross the network. There is no silent fallback: a content
filter that cannot be applied ends the command with status 2 and the reason. --filter is
ros2 topic's: a Python expression on the message m, evaluated in this process."""

_TOPIC_EPILOG = f"""\
examples:
  {_PROG} topic echo /weather --content-filter "temperature > %0" --content-filter-params 30.0
  {_PROG} topic hz /chatter std_msgs/msg/String --filter "m.data == 'hello'"

  Call `{_PROG} topic <command> -h` for more detailed usage."""


def _verb(name: str) -> ModuleType:
    return importlib.import_module(f'cft_action.verb.{name}')


def _add_verb_parser(subparsers, name: str, module: ModuleType) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        name, help=module.HELP, description=module.DESCRIPTION, epilog=module.EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    module.add_arguments(parser)
    parser.set_defaults(_verb_module=module, _verb_parser=parser)
    return parser


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=_PROG,
        description=f'{_PROG} is a command-line tool for content-filtered ROS 2 action feedback '
                    'and topics.',
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=f'  Call `{_PROG} <command> -h` for more detailed usage.')
    commands = parser.add_subparsers(title='Commands', dest='_command', metavar='<command>')
    _add_verb_parser(commands, 'guard', _verb('guard'))
    topic = commands.add_parser(
        'topic', help=_TOPIC_HELP, description=_TOPIC_DESCRIPTION, epilog=_TOPIC_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    topic.set_defaults(_verb_module=None, _verb_parser=topic)
    verbs = topic.add_subparsers(title='Commands', dest='_verb', metavar='<command>')
    for name in TOPIC_VERBS:
        _add_verb_parser(verbs, name, _verb(name))
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of the ``cft-action`` console script; returns the exit status."""
    parser = _build_parser()
    args = parser.parse_args(argv)
    if not args._command:
        parser.print_help()
        return 0
    if args._verb_module is None:  # `cft-action topic` without a verb
        args._verb_parser.print_help()
        return 0
    return args._verb_module.main(args, args._verb_parser, args._verb_parser.prog)


if __name__ == '__main__':
    sys.exit(main())
