# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""``cft-action topic hz``: the rate of the messages of a topic that pass its filters, as
``ros2 topic hz`` prints it."""

from __future__ import annotations

import argparse
import math
import time
from collections import deque
from typing import Any, Callable, Optional

from cft_action.topics import topic_api
from cft_action.verb import examples

DEFAULT_WINDOW_SIZE = 10000

HELP = 'Print the average publishing rate to screen'

DESCRIPTION = """\
Print the average rate, and the minimum, maximum and standard deviation of the intervals, of the
messages of a topic that pass the content filter and --filter, once a second.

The content filter (--content-filter, DDS-SQL) is applied by the middleware: messages that do not
match never reach this process. --filter is ros2 topic hz's: a Python expression on the message m,
evaluated in this process."""

EPILOG = examples(
    'cft-action topic hz /strings std_msgs/msg/String --content-filter "data = %0" '
    '--content-filter-params world',
    'cft-action topic hz /chatter --content-filter "data LIKE \'Hello%\'" --window 100',
    'cft-action topic hz /chatter --filter "m.data.startswith(\'Hello\')"')


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """ros2cli's ``hz`` arguments, the content filter, the QoS and ``--timeout``."""
    topic_api.add_topic_arguments(parser, "listen to (e.g. '/chatter')",
                                  window=DEFAULT_WINDOW_SIZE)
    topic_api.add_python_filter_argument(
        parser, 'only measure messages matching the specified Python expression (on m, the '
                'message), evaluated in this process after the content filter')
    parser.add_argument(
        '--wall-time', dest='use_wtime', action='store_true',
        help="Accepted for ros2 topic hz's command lines: the rate is always measured in wall "
             'time here (this tool has no simulated clock)')


class RateWindow:
    """The intervals between the last ``window`` messages, as ``ros2 topic hz`` keeps them."""

    def __init__(self, window: int) -> None:
        self.intervals: deque[float] = deque(maxlen=window)
        self.last: Optional[float] = None
        self.fresh = False

    def tick(self, now: float) -> None:
        """Count a message that arrived at ``now`` (monotonic seconds)."""
        if self.last is not None:
            self.intervals.append(now - self.last)
            self.fresh = True
        self.last = now

    def report(self) -> Optional[str]:
        """The rate and the intervals' statistics, or None when no message came since the last."""
        if not self.fresh or not self.intervals:
            return None
        self.fresh = False
        n = len(self.intervals)
        mean = sum(self.intervals) / n
        rate = 1.0 / mean if mean > 0 else 0.0
        std_dev = math.sqrt(sum((x - mean) ** 2 for x in self.intervals) / n)
        return (f'average rate: {rate:.3f}\n\tmin: {min(self.intervals):.3f}s max: '
                f'{max(self.intervals):.3f}s std dev: {std_dev:.5f}s window: {n}')


def main(args: argparse.Namespace, parser: argparse.ArgumentParser, prog: str) -> int:
    """Print the rate of the messages that pass the filters, once a second."""
    del parser
    window = RateWindow(args.window)
    keep: Optional[Callable[[Any], bool]] = None

    def on_message(msg: Any, _info: Any) -> None:
        if keep is None or keep(msg):
            window.tick(time.monotonic())

    def body(session: topic_api.Session) -> int:
        nonlocal keep
        keep = topic_api.python_filter(args.filter_expr)
        _, deadline = topic_api.start(session, args, on_message)
        return topic_api.report_loop(session, deadline, window.report)

    return topic_api.run(prog, body)
