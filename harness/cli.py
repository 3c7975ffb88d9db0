"""Command-line value types and options shared by the demos and benchmarks."""

from __future__ import annotations

import argparse
from typing import Callable, Iterable, Optional


def int_list(text: str) -> list[int]:
    """``'1,4,16'`` -> ``[1, 4, 16]``, in the given order."""
    return [int(v) for v in text.split(',') if v.strip()]


def float_list(text: str) -> list[float]:
    """``'10,100'`` -> ``[10.0, 100.0]``, in the given order."""
    return [float(v) for v in text.split(',') if v.strip()]


def name_list(known: Iterable[str]) -> Callable[[str], list[str]]:
    """An argparse type: a comma-separated list of names, each one of ``known``."""
    choices = list(known)

    def parse(text: str) -> list[str]:
        names = [n.strip() for n in text.split(',') if n.strip()]
        unknown = sorted(set(names) - set(choices))
        if unknown:
            raise argparse.ArgumentTypeError(f'unknown {", ".join(unknown)}; '
                                             f'from: {", ".join(choices)}')
        return names

    return parse


def feedback_depth(text: str) -> Optional[int]:
    """``'10'`` -> 10; ``'all'`` -> None (the feedback writer as deep as every queue)."""
    return None if text.strip().lower() == 'all' else int(text)


def add_server_feedback_depth(parser: argparse.ArgumentParser,
                              default: Optional[int] = None) -> None:
    """``--server-feedback-depth N|all``: the load server's feedback writer alone keeps N samples
    (:attr:`harness.load.LoadSpec.server_feedback_depth`); ``all``: as deep as every queue, which
    holds all of a phase's feedback. ``default`` None is ``all``."""
    # A string default goes through ``type`` too: the help then shows ``all`` rather than None.
    parser.add_argument('--server-feedback-depth', type=feedback_depth, metavar='N|all',
                        default='all' if default is None else str(default),
                        help="the server's feedback writer alone keeps this many samples (rclpy's "
                             "default: 10); all: as deep as every queue, which holds all of a "
                             "phase's feedback")
