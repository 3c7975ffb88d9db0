# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""``cft-action action info <name>``: an action's client and server nodes, as ``ros2 action info``
prints them, with whether each server runs the guard and where each client's feedback is
filtered."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any, Optional

from cft_action.action import action_api
from cft_action.topics.topic_api import TopicToolError
from cft_action.verb import examples

HELP = 'Print information about an action'

DESCRIPTION = """\
Print information about an action, as `ros2 action info` does, and, from the discovery data:

- after each server node, `guard: yes` when its process runs the cft_action server guard
  (`cft-action guard`), `guard: no` when it does not, `guard: unknown` when no feedback writer of
  it was seen;
- after each client node, where other goals' feedback is dropped, in the words of
  cft_action's FeedbackFilterState.filtered_in: `writer` (the server's writer does not send it),
  `reader` (it crosses the network and the client's DDS reader drops it), `none` (not filtered:
  a plain rclpy client), or `unknown`.

The columns say what the discovery data say. A writer never filters for a reader in its own
process; without the guard, for at most 32 readers."""

EPILOG = examples('cft-action action info /fibonacci -t',
                  'cft-action action info /fibonacci --json')


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """ros2cli's ``action_name``, ``-t/--show-types`` and ``-c/--count``, ``--json`` and
    ``--spin-time``."""
    parser.add_argument('action_name',
                        help="Name of the ROS action to get info (e.g. '/fibonacci')")
    parser.add_argument('-t', '--show-types', action='store_true',
                        help='Additionally show the action type')
    parser.add_argument('-c', '--count', action='store_true',
                        help='Only display the number of action clients and action servers')
    action_api.add_arguments(parser)


def _guard_word(guard: Optional[bool]) -> str:
    return 'unknown' if guard is None else ('yes' if guard else 'no')


def _line(node: str, types: list[str], show_types: bool, note: str) -> str:
    shown = f'{node} [{", ".join(types)}]' if show_types else node
    return f'    {shown} ({note})'


def main(args: argparse.Namespace, parser: argparse.ArgumentParser, prog: str) -> int:
    """Print the action's clients and servers (with ``-c`` only how many)."""
    del parser

    def body(node: Any) -> int:
        from cft_action import _rcl

        try:
            name = action_api.expand_action_name(node, args.action_name)
        except Exception as e:  # ValueError, or rclpy's InvalidTopicNameException
            raise TopicToolError(str(e)) from e
        clients, servers = action_api.get_action_clients_and_servers(node, name)
        unknown = _rcl.reader_filters_reason()
        if args.json:
            document = {
                'action': name,
                'clients': [{'node': c.node, 'types': c.types,
                             'feedback_filtered_in': c.filtered_in,
                             'feedback_filter_classes': c.filter_classes} for c in clients],
                'servers': [{'node': s.node, 'types': s.types, 'guard': s.guard}
                            for s in servers]}
            if unknown:
                document['unknown_reason'] = unknown
            print(json.dumps(document))
            return 0
        print(f'Action: {args.action_name}')
        print(f'Action clients: {len(clients)}')
        if not args.count:
            for client in clients:
                print(_line(client.node, client.types, args.show_types,
                            f'feedback filtered in: {client.filtered_in}'))
        print(f'Action servers: {len(servers)}')
        if not args.count:
            for server in servers:
                print(_line(server.node, server.types, args.show_types,
                            f'guard: {_guard_word(server.guard)}'))
        if unknown and not args.count:
            print(f'{prog}: feedback filters may be unknown: {unknown}', file=sys.stderr)
        return 0

    return action_api.run(prog, args, body)
