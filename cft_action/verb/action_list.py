# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""``cft-action action list``: the actions in the ROS graph, as ``ros2 action list`` prints them."""

from __future__ import annotations

import argparse
import json
from typing import Any

from cft_action.action import action_api
from cft_action.verb import examples

HELP = 'Output a list of action names'

DESCRIPTION = """\
Output a list of action names, as `ros2 action list` does.

This command never uses the ros2 daemon: it spins its own node for --spin-time seconds to discover
the graph. `cft-action action info <name>` tells, per action, which servers run the guard and
where each client's feedback is filtered."""

EPILOG = examples('cft-action action list -t', 'cft-action action list --json')


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """ros2cli's ``-t/--show-types`` and ``-c/--count-actions``, ``--json`` and ``--spin-time``."""
    parser.add_argument('-t', '--show-types', action='store_true',
                        help='Additionally show the action type')
    parser.add_argument('-c', '--count-actions', action='store_true',
                        help='Only display the number of actions discovered')
    action_api.add_arguments(parser)


def main(args: argparse.Namespace, parser: argparse.ArgumentParser, prog: str) -> int:
    """Print the actions (with ``-t`` their types; with ``-c`` only how many)."""
    del parser

    def body(node: Any) -> int:
        actions = action_api.get_action_names_and_types(node)
        if args.json:
            print(json.dumps({'count': len(actions)} if args.count_actions else
                             [{'name': name, 'types': types} for name, types in actions]))
        elif args.count_actions:
            print(len(actions))
        else:
            for name, types in actions:
                print(f'{name} [{", ".join(types)}]' if args.show_types else name)
        return 0

    return action_api.run(prog, args, body)
