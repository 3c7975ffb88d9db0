"""Command-line value types shared by the demos and benchmarks (argparse ``type=`` callables)."""

from __future__ import annotations

import argparse
from typing import Callable, Iterable


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
