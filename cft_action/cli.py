# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The ``cft-action`` command line, in the style of ros2cli.

    cft-action guard -- python my_action_server.py   # run a server with the guard preloaded
    cft-action guard --print-path                     # the library to put in LD_PRELOAD yourself
    cft-action topic echo /weather --content-filter "temperature > %0" --content-filter-params 30.0
    cft-action topic hz /chatter std_msgs/msg/String --filter "m.data.startswith('hello')"
    cft-action action info /fibonacci                 # which servers run the guard, and more

Each verb is a module of :mod:`cft_action.verb` with its help texts, ``add_arguments`` and
``main``; this module only builds the parsers from them and dispatches.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from types import ModuleType
from typing import Optional, Sequence

from cft_action.verb import ACTION_VERBS, TOPIC_VERBS

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

_ACTION_HELP = 'Various action related sub-commands, with where feedback is filtered'

_ACTION_DESCRIPTION = """\
Various action related sub-commands, as ros2 action's, which also tell from the discovery data
which servers run the cft_action server guard and where each client's feedback is filtered."""

_ACTION_EPILOG = f"""\
examples:
  {_PROG} action list -t
  {_PROG} action info /fibonacci --json

  Call `{_PROG} action <command> -h` for more detailed usage."""


def _verb(name: str) -> ModuleType:
    return importlib.import_module(f'cft_action.verb.{name}')


def _add_verb_parser(subparsers, name: str, module: ModuleType) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        name, help=module.HELP, description=module.DESCRIPTION, epilog=module.EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    module.add_arguments(parser)
    parser.set_defaults(_verb_module=module, _verb_parser=parser)
    return parser


def _add_command(commands, name: str, help_text: str, description: str, epilog: str,
                 verbs: dict[str, str]) -> None:
    """A command of verbs (``topic``, ``action``): ``verbs`` maps each verb to its module."""
    command = commands.add_parser(
        name, help=help_text, description=description, epilog=epilog,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    command.set_defaults(_verb_module=None, _verb_parser=command)
    subparsers = command.add_subparsers(title='Commands', dest='_verb', metavar='<command>')
    for verb, module in verbs.items():
        _add_verb_parser(subparsers, verb, _verb(module))


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=_PROG,
        description=f'{_PROG} is a command-line tool for content-filtered ROS 2 action feedback '
                    'and topics.',
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=f'  Call `{_PROG} <command> -h` for more detailed usage.')
    commands = parser.add_subparsers(title='Commands', dest='_command', metavar='<command>')
    _add_command(commands, 'action', _ACTION_HELP, _ACTION_DESCRIPTION, _ACTION_EPILOG,
                 ACTION_VERBS)
    _add_verb_parser(commands, 'guard', _verb('guard'))
    _add_command(commands, 'topic', _TOPIC_HELP, _TOPIC_DESCRIPTION, _TOPIC_EPILOG,
                 {name: name for name in TOPIC_VERBS})
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of the ``cft-action`` console script; returns the exit status."""
    parser = _build_parser()
    args = parser.parse_args(argv)
    if not args._command:
        parser.print_help()
        return 0
    if args._verb_module is None:  # `cft-action topic` or `action` without a verb
        args._verb_parser.print_help()
        return 0
    return args._verb_module.main(args, args._verb_parser, args._verb_parser.prog)


if __name__ == '__main__':
    sys.exit(main())
