# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""What ``cft-action action list`` and ``action info`` read from the ROS graph, as
ros2cli's ``ros2action.api``, plus where each action's feedback is filtered.

The servers and clients of an action are those ``ros2 action info`` finds (the publishers and
subscribers of its feedback topic), named as ros2cli names nodes (``/ns/name``). Beyond that,
from the discovery data this process reads (cft_action/native/reader/_writer_marks.c):

- per server node, whether its process runs the guard: the guard marks every writer of its
  process (cft_action/native/guard/_guard_writer_qos.c), so the node's feedback writers say it;
- per client node, where other goals' feedback is dropped, in the words of
  :attr:`cft_action.FeedbackFilterState.filtered_in`, from the content filter class of the node's
  feedback readers: none is ``'none'``; DDS-SQL is ``'writer'`` (every Fast DDS writer filters it);
  one of the library's classes is ``'writer'`` where the servers' writers are guarded and
  ``'reader'`` where they are not; another class is ``'reader'`` (no writer knows it).

:mod:`cft_action._rcl` must be imported before the process's first participant exists, or the
readers and writers discovered before are ``'unknown'``.
"""

from __future__ import annotations

import argparse
import time
from typing import Any, Callable, NamedTuple, Optional

#: Seconds to spin for discovery. ros2cli's direct node (``ros2cli.node.direct``) spins 0.5 s, and
#: ``ros2 action`` normally asks the daemon, which has long discovered the graph. These verbs have
#: no daemon, and a new participant may learn of the others only from their periodic announcements
#: (Fast DDS's default period is 3 s): the first other node came after 0.02-3.3 s in 20 runs here.
DEFAULT_SPIN_TIME = 4.0

#: ``FeedbackFilterState.filtered_in``'s words, and this module's for a node seen without it.
FILTERED_IN = ('writer', 'reader', 'none', 'unknown')


class ServerInfo(NamedTuple):
    """One action server node: its name, the action's types, and whether it runs the guard
    (None: unknown, e.g. no feedback writer seen yet)."""

    node: str
    types: list[str]
    guard: Optional[bool]


class ClientInfo(NamedTuple):
    """One action client node: its name, the action's types, where other goals' feedback is
    dropped (:data:`FILTERED_IN`; several, comma-separated, for a node whose clients differ), and
    its feedback readers' filter classes (``''`` for none, None where unknown)."""

    node: str
    types: list[str]
    filtered_in: str
    filter_classes: list[Optional[str]]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments every action verb has: ``--json``, and ros2cli's ``--spin-time`` and
    ``--no-daemon`` (accepted for scripts: these verbs never use the daemon)."""
    parser.add_argument('--json', action='store_true',
                        help='Print one JSON document instead of text, for scripts')
    parser.add_argument('--spin-time', type=float, default=DEFAULT_SPIN_TIME,
                        help='Spin time in seconds to wait for discovery (default: '
                             f'{DEFAULT_SPIN_TIME})')
    parser.add_argument('--no-daemon', action='store_true',
                        help='Accepted as ros2cli\'s; the daemon is never used')


def run(prog: str, args: argparse.Namespace, body: Callable[[Any], int]) -> int:
    """Discover the graph for ``args.spin_time`` seconds, then ``body(node)``; its exit status.

    The library's discovery reading is installed first (importing :mod:`cft_action._rcl`), before
    the session's participant exists, so that every endpoint's discovery data is read.
    """
    from cft_action import _rcl  # noqa: F401 (installs the discovery reading)
    from cft_action.topics import topic_api

    def discovered(session: topic_api.Session) -> int:
        deadline = time.monotonic() + max(0.0, args.spin_time)
        while time.monotonic() < deadline:
            session.spin_once(min(0.1, deadline - time.monotonic()))
        return body(session.node)

    return topic_api.run(prog, discovered)


def node_full_name(name: str, namespace: str) -> str:
    """``/ns/name``, as ros2cli's ``ros2node.api.get_node_names`` names a node."""
    return namespace + ('' if namespace.endswith('/') else '/') + name


def get_action_names_and_types(node: Any) -> list[tuple[str, list[str]]]:
    """Every action in the graph and its types, sorted by name (``ros2 action list``)."""
    from rclpy.action.graph import get_action_names_and_types as names_and_types

    return sorted(names_and_types(node))


def expand_action_name(node: Any, action_name: str) -> str:
    """The fully qualified action name, as ``ros2 action info`` expands it.

    :raises ValueError: or rclpy's ``InvalidTopicNameException``, for an invalid name.
    """
    from rclpy.expand_topic_name import expand_topic_name
    from rclpy.validate_full_topic_name import validate_full_topic_name

    expanded = expand_topic_name(action_name, node.get_name(), node.get_namespace())
    validate_full_topic_name(expanded)
    return expanded


def get_action_clients_and_servers(
        node: Any, action_name: str) -> tuple[list[ClientInfo], list[ServerInfo]]:
    """The client and server nodes of the fully qualified ``action_name``, sorted by name.

    As rcl_action's graph queries (``rcl_action_get_client_names_and_types_by_node``), which
    ``ros2 action info`` asks per node, a client is a node that subscribes to the action's
    feedback topic and a server one that publishes it, its type the topic's without
    ``_FeedbackMessage``. They are asked here per topic, whose endpoints name their nodes: the
    queries by node answer for the first node of a name, so ros2cli lists two servers of one name
    (on two actions) as two servers of each.
    """
    feedback = f'{action_name}/_action/feedback'
    readers = _endpoints_by_node(node.get_subscriptions_info_by_topic(feedback))
    writers = _endpoints_by_node(node.get_publishers_info_by_topic(feedback))
    clients = [ClientInfo(name, types, _filtered_in(classes, writers), classes)
               for name, (types, gids) in readers.items()
               for classes in [[_reader_class(gid) for gid in gids]]]
    servers = [ServerInfo(name, types, _guarded(gids)) for name, (types, gids) in writers.items()]
    return sorted(clients), sorted(servers)


_TYPE_SUFFIX = '_FeedbackMessage'


def _endpoints_by_node(endpoints: Any) -> dict[str, tuple[list[str], list[bytes]]]:
    """``{node: (action types, endpoint GIDs)}`` of a feedback topic's endpoints."""
    by_node: dict[str, tuple[list[str], list[bytes]]] = {}
    for endpoint in endpoints:
        types, gids = by_node.setdefault(
            node_full_name(endpoint.node_name, endpoint.node_namespace), ([], []))
        action_type = endpoint.topic_type
        if action_type.endswith(_TYPE_SUFFIX):
            action_type = action_type[:-len(_TYPE_SUFFIX)]
        if action_type not in types:
            types.append(action_type)
        gids.append(bytes(endpoint.endpoint_gid))
    return by_node


def _reader_class(gid: bytes) -> Optional[str]:
    from cft_action import _rcl

    return _rcl.reader_filter_class(gid)


def _guarded(gids: list[bytes]) -> Optional[bool]:
    """Whether every one of a node's feedback writers is a guarded one."""
    from cft_action import _rcl

    known = [_rcl.writer_filters(gid) for gid in gids]
    if not known or None in known:
        return None
    return all(known)


def _filtered_in(classes: list[Optional[str]],
                 writers: dict[str, tuple[list[str], list[bytes]]]) -> str:
    """:data:`FILTERED_IN` of a client node with feedback readers of these filter classes."""
    from cft_action import _rcl

    library_classes = (_rcl.UUID_FILTER_CLASS, _rcl.NODE_FILTER_CLASS)
    guarded = [_guarded(gids) for _, gids in writers.values()]
    words = set()
    for filter_class in classes:
        if filter_class is None:
            words.add('unknown')
        elif not filter_class:
            words.add('none')
        elif filter_class == 'DDSSQL':
            words.add('writer')
        elif filter_class not in library_classes or False in guarded:
            words.add('reader')
        else:
            words.add('writer' if guarded and all(guarded) else 'unknown')
    return ', '.join(sorted(words, key=FILTERED_IN.index)) or 'unknown'
