"""The report step of every benchmark and demo: progress lines, figures and tables.

A benchmark is spec -> run -> report: its command line is the spec, the run goes through the rest
of ``harness`` and writes a results file, and the report (these tables, and the plots of
:mod:`harness.plot`) is made from the results alone, so that ``--markdown RESULTS`` can redraw it.
"""

from __future__ import annotations

import argparse
import datetime
import json
import platform
import sys
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

from harness.machine import environment_facts
from harness.proc import ROOT


def add_results_arguments(parser: argparse.ArgumentParser) -> None:
    """``--out FILE`` (where the results go) and ``--markdown RESULTS`` (run nothing: print the
    tables of a results file), for :func:`results_start` and :func:`markdown_only`."""
    parser.add_argument('--out', type=Path, help='results file (default: benchmarks/results/)')
    parser.add_argument('--markdown', type=Path, help='print the tables of a results file')


def markdown_only(args: argparse.Namespace, present: Callable[[dict[str, Any]], str]) -> bool:
    """With ``--markdown RESULTS``, print ``present(results)`` and return True: run nothing."""
    if args.markdown is None:
        return False
    print(present(json.loads(args.markdown.read_text())))
    return True


def results_start(benchmark: str, out: Optional[Path], argv: Optional[Sequence[str]]
                  ) -> tuple[Path, dict[str, Any]]:
    """Where a benchmark's results go, and the fields every results file begins with.

    :param benchmark: the module's name under ``benchmarks`` (``c_server``).
    :param out: the ``--out`` given, else ``benchmarks/results/<name>-<date>-<host>.json``.
    :param argv: the arguments of ``main``, or None for ``sys.argv``'s.
    :return: (the file, ``{'benchmark', 'started', 'command', 'machine'}``).
    """
    started = datetime.datetime.now(datetime.timezone.utc)
    name = benchmark.replace('_', '-')
    output = out or (ROOT / 'benchmarks' / 'results' /
                     f'{name}-{started.date().isoformat()}-{platform.node()}.json')
    arguments = sys.argv[1:] if argv is None else argv
    return output, {'benchmark': benchmark, 'started': started.isoformat(timespec='seconds'),
                    'command': f'python -m benchmarks.{benchmark} ' + ' '.join(arguments),
                    'machine': environment_facts()}


def results_end(output: Path, result: dict[str, Any],
                present: Callable[[dict[str, Any]], str]) -> None:
    """Write ``result`` to ``output`` (:func:`results_start`'s) and print ``present(result)`` and
    where the file is."""
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(json.dumps(result, indent=1))
    print(present(result))
    print(f'results: {output}')


def alternating_main(benchmark: str, argv: list[str], doc: str,
                     add_arguments: Callable[[argparse.ArgumentParser], None],
                     configs: Sequence[str],
                     run: Callable[[argparse.Namespace, list[str]], dict[str, Any]],
                     present: Callable[[dict[str, Any]], str]) -> None:
    """The command line of a benchmark that runs server configurations side by side, alternating:
    ``--rounds``, its own arguments (``add_arguments``), ``--unguarded`` (the configuration named
    ``unguarded`` runs only with it), ``--out`` and ``--markdown``. ``run(args, chosen
    configurations)`` gives the results' fields beyond the header and ``configs``."""
    parser = argparse.ArgumentParser(description=doc.split('\n\n')[0])
    parser.add_argument('--rounds', type=int, default=3)
    add_arguments(parser)
    parser.add_argument('--unguarded', action='store_true', help='also a server without the guard')
    add_results_arguments(parser)
    args = parser.parse_args(argv)
    if markdown_only(args, present):
        return
    output, header = results_start(benchmark, args.out, argv)
    chosen = [c for c in configs if args.unguarded or c != 'unguarded']
    results_end(output, {**header, 'configs': chosen, **run(args, chosen)}, present)


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
