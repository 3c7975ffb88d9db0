# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The hazard matrix: which filter events crash a Fast DDS action server, guard on and off.

With Fast DDS 2.14 (Jazzy), events at a filtered reader that the server's feedback writer must
process can segfault the **server** (eProsima/Fast-DDS issue 4878; ``docs/SAFETY.md``). This script
reproduces them, cell by cell, with and without the guard (:mod:`cft_action.guard`):

- ``update``: a live filtered reader changes its filter every ``--interval`` s (two expressions
  that match nothing, alternated, so each update is a real change), up to ``--updates`` times;
- ``destroy``: a filtered ``cft_action.ActionClient`` (``client`` mode) is created, matched and
  destroyed, up to ``--destroys`` times, in one process;
- ``create``: filtered clients are created and kept, up to ``--creates`` of them, in one process
  (the server is stopped before that process exits, so its exit is not counted here);
- ``exit``: a process creates ``--k`` filtered clients, then exits normally; up to ``--exits``
  processes, one after the other.

The server (:mod:`harness.server`, rclpy's default queues) publishes feedback every PERIOD s
(``--periods``, default 0.0005 0.01 0.1) from a ticker thread to one goal that an ordinary,
unfiltered client keeps running; the feedback ``sequence`` is ``small`` (the server's 3-int32
header, 12 bytes) or ``10k`` (2500 int32, 10,000 bytes) (``--payloads``). Each cell runs
to the first server crash or to its bound of events, with the guard ``on`` and ``off``
(``--guard``). A crashed server's core (``ulimit -c unlimited`` in the server, cwd a fresh
directory) is read with gdb for the crashing thread's backtrace; without gdb or a core, the exit
signal is all that is recorded. A crash is evidence: cells are never retried.

Each cell has a ROS domain of its own (random, 1..101), localhost-only discovery and a unique action
name. Every wait is bounded; every process started is stopped by this script, by its pid.

Examples::

    python -m benchmarks.hazard --events update --periods 0.0005 --payloads small --updates 50
    python -m benchmarks.hazard --events update destroy --periods 0.0005 0.01 --payloads small \\
        --updates 200 --destroys 30 --json hazard.json

A cell is :func:`harness.hazard.run_cell`; its child processes are the roles of that module.
"""

from __future__ import annotations

import argparse
import datetime
import json
import shutil
import sys
from pathlib import Path
from typing import Any, Optional

from harness.crash import crash_site, machine_line
from harness.hazard import EVENTS, PAYLOADS, Cell, describe, run_cell


def markdown_table(results: list[dict[str, Any]]) -> str:
    rows = ['| event | feedback period | payload | guard | bound | result | feedback/s '
            '| server crash site (innermost Fast DDS frames) |',
            '|---|---|---|---|---|---|---|---|']
    for r in results:
        event = r['event'] + (f' (k={r["k"]})' if r.get('k') else '')
        rows.append(f'| {event} | {r["period_ms"]:g} ms | {r["payload"]} | '
                    f'{"on" if r["guard"] else "off"} | {r["bound"]} | {describe(r)} | '
                    f'{r.get("feedback_per_s", "")} | {crash_site(r)} |')
    return '\n'.join(rows)


def main(argv: Optional[list[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = argparse.ArgumentParser(
        description=__doc__.split('\n\n')[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='Every cell: a fresh server, goal client and event client; cells never retried.')
    parser.add_argument('--events', nargs='+', choices=EVENTS, default=list(EVENTS))
    parser.add_argument('--periods', nargs='+', type=float, default=[0.0005, 0.01, 0.1],
                        metavar='S', help='server feedback periods in seconds')
    parser.add_argument('--payloads', nargs='+', choices=list(PAYLOADS),
                        default=list(PAYLOADS))
    parser.add_argument('--guard', nargs='+', choices=['on', 'off'], default=['on', 'off'])
    parser.add_argument('--updates', type=int, default=300, help='bound of filter updates')
    parser.add_argument('--interval', type=float, default=0.02,
                        help='seconds between filter updates')
    parser.add_argument('--destroys', type=int, default=30, help='bound of destroyed readers')
    parser.add_argument('--creates', type=int, default=30, help='bound of created readers')
    parser.add_argument('--exits', type=int, default=10, help='bound of exiting processes')
    parser.add_argument('--k', type=int, default=10,
                        help='filtered readers in each exiting process')
    parser.add_argument('--settle', type=float, default=0.3,
                        help='seconds for discovery after each create or destroy')
    parser.add_argument('--reps', type=int, default=1, help='runs of each cell')
    parser.add_argument('--keep-cores', action='store_true',
                        help='keep core files and work directories (printed)')
    parser.add_argument('--json', metavar='PATH', help='also write the results as JSON')
    parser.add_argument('--list', action='store_true', help='only list the selected cells')
    opts = parser.parse_args(argv)

    bounds = {'update': opts.updates, 'destroy': opts.destroys, 'create': opts.creates,
              'exit': opts.exits}
    cells = [Cell(event, period, payload, g == 'on', bounds[event])
             for event in opts.events for period in opts.periods
             for payload in opts.payloads for g in opts.guard for _ in range(opts.reps)]
    if opts.list:
        for cell in cells:
            print(cell.label(), 'bound', cell.bound)
        return 0
    started_at = datetime.datetime.now(datetime.timezone.utc)
    header = {'date_utc': started_at.strftime('%Y-%m-%d %H:%M'), 'machine': machine_line(),
              'command': 'python -m benchmarks.hazard ' + ' '.join(argv),
              'gdb': shutil.which('gdb') is not None,
              'core_pattern': Path('/proc/sys/kernel/core_pattern').read_text().strip()
              if Path('/proc/sys/kernel/core_pattern').exists() else None}
    print(json.dumps(header), flush=True)
    results = []
    for n, cell in enumerate(cells, 1):
        print(f'[{n}/{len(cells)}] {cell.label()} bound {cell.bound} ...', flush=True)
        outcome = run_cell(cell, opts)
        results.append(outcome)
        print(f'    -> {describe(outcome)}; server {outcome.get("server", "?")}; '
              f'{outcome.get("feedback_per_s", "?")} feedback/s; '
              f'{outcome.get("cell_wall_s")} s', flush=True)
        if outcome.get('backtrace'):
            print('    backtrace:\n      ' + '\n      '.join(outcome['backtrace'][:12]),
                  flush=True)
        if 'error' in outcome:
            for tail in outcome.get('logs', []):
                print('    ' + tail.replace('\n', '\n    '), flush=True)
    print()
    print(markdown_table(results))
    if opts.json:
        Path(opts.json).write_text(json.dumps({'header': header, 'results': results}, indent=1))
        print(f'\nresults written to {opts.json}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
