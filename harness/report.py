"""The report step of every benchmark and demo: progress lines, figures and tables.

A benchmark is spec -> run -> report: its command line is the spec, the run goes through the rest
of ``harness`` and writes a results file, and the report (these tables, and the plots of
:mod:`harness.plot`) is made from the results alone, so that ``--markdown RESULTS`` can redraw it.
"""

from __future__ import annotations

from typing import Optional, Sequence


def say(*words: object) -> None:
    """A progress line, flushed at once (the runs take minutes, and their output is piped)."""
    print(*words, flush=True)


def fmt(value: Optional[float], spec: str = '.0f') -> str:
    """``value`` formatted by ``spec``; ``-`` for a figure that was not measured (``None``)."""
    return '-' if value is None else format(value, spec)


def grid(rows: Sequence[Sequence[str]]) -> str:
    """A plain-text table for the terminal: the first row is the header, underlined; the first
    column is left-aligned, the others right-aligned."""
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = []
    for n, row in enumerate(rows):
        lines.append('  '.join(cell.ljust(w) if i == 0 else cell.rjust(w)
                               for i, (cell, w) in enumerate(zip(row, widths))))
        if n == 0:
            lines.append('  '.join('-' * w for w in widths))
    return '\n'.join(lines)


def markdown_row(cells: Sequence[str]) -> str:
    """One row of a Markdown table."""
    return '| ' + ' | '.join(cells) + ' |'


def markdown_table(head: Sequence[str], rows: Sequence[Sequence[str]],
                   align: Optional[Sequence[str]] = None) -> list[str]:
    """A Markdown table as lines: ``head``, the separator, then ``rows``.

    ``align`` gives each column's separator cell (``'---'``, ``'---:'``); default ``'---'``.
    """
    separator = align if align is not None else ['---'] * len(head)
    return [markdown_row(head), '|' + '|'.join(separator) + '|',
            *(markdown_row(row) for row in rows)]
