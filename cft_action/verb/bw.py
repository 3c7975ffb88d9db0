# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""``cft-action topic bw``: the bandwidth of the messages of a topic that pass its content filter,
as ``ros2 topic bw`` prints it.

Jazzy's ``ros2 topic bw`` has no Python ``--filter``, and neither has this verb: it counts the
serialized messages without deserializing them.
"""

from __future__ import annotations

import argparse
import time
from collections import deque
from typing import Any, Optional

from cft_action.topics import topic_api
from cft_action.verb import examples

DEFAULT_WINDOW_SIZE = 100

HELP = 'Display bandwidth used by topic'

DESCRIPTION = """\
Display the bandwidth used by the messages of a topic that pass the content filter.

The content filter (--content-filter, DDS-SQL) is applied by the middleware: messages that do not
match never reach this process."""

EPILOG = examples(
    'cft-action topic bw /strings std_msgs/msg/String --content-filter "data = %0" '
    '--content-filter-params world',
    'cft-action topic bw /scan --content-filter "ranges[0] < 0.5" --window 50')


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """ros2cli's ``bw`` arguments, the content filter, the QoS and ``--timeout``."""
    topic_api.add_topic_arguments(parser, 'monitor for bandwidth utilization',
                                  window=DEFAULT_WINDOW_SIZE)


def _bytes(value: float) -> str:
    for unit, size in (('MB', 1e6), ('KB', 1e3)):
        if value >= size:
            return f'{value / size:.2f} {unit}'
    return f'{value:.2f} B'


class BandwidthWindow:
    """Arrival times and sizes of the last ``window`` messages, as ``ros2 topic bw`` keeps them."""

    def __init__(self, window: int) -> None:
        self.samples: deque[tuple[float, int]] = deque(maxlen=window)

    def add(self, data: bytes, _info: Any) -> None:
        """Count a serialized message that arrived now."""
        self.samples.append((time.monotonic(), len(data)))

    def report(self) -> Optional[str]:
        """The bandwidth and the message sizes, or None before two messages."""
        if len(self.samples) < 2:
            return None
        sizes = [size for _, size in self.samples]
        elapsed = time.monotonic() - self.samples[0][0]
        rate = sum(sizes) / elapsed if elapsed > 0 else 0.0
        mean = sum(sizes) / len(sizes)
        return (f'{_bytes(rate)}/s from {len(sizes)} messages\n\tMessage size mean: '
                f'{_bytes(mean)} min: {_bytes(min(sizes))} max: {_bytes(max(sizes))}')


def main(args: argparse.Namespace, parser: argparse.ArgumentParser, prog: str) -> int:
    """Print the bandwidth of the messages that pass the content filter, once a second."""
    del parser
    window = BandwidthWindow(args.window)

    def body(session: topic_api.Session) -> int:
        topic, deadline = topic_api.start(session, args, window.add, raw=True)
        print(f'Subscribed to [{topic}]', flush=True)
        return topic_api.report_loop(session, deadline, window.report)

    return topic_api.run(prog, body)
