"""When does a parameter event filter change reach the publishers? Without and with the proof.

A :class:`cft_action.ParameterEventHandler` change travels to the ``/parameter_events`` writers by
discovery, and until it arrives they apply the previous filter. Each run creates a handler that
watches node ``a`` of three (``node = %0``), then adds a parameter event callback (``node = node``),
waits until every node's writer has matched a reader of this process (what a test would check),
and publishes a burst of 3 events on each node:

- ``--mode burst``: at once;
- ``--mode wait``: after ``ParameterEventHandler.wait_for_filter``.

It counts the runs in which fewer than the 9 events arrived, and times ``wait_for_filter``::

    python -m benchmarks.filter_arrival --runs 60 --mode burst
    python -m benchmarks.filter_arrival --runs 60 --mode wait

The nodes' process (:mod:`harness.param_nodes`) runs under the guard. Results go to
``benchmarks/results/filter-arrival-<mode>-<date>-<host>.json``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time
import uuid
from pathlib import Path

from harness.domain import unused_domain

REPO = Path(__file__).resolve().parent.parent
os.environ.setdefault('ROS_DOMAIN_ID', str(unused_domain()))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

from cft_action import guard  # noqa: E402
from cft_action.parameters.parameter_events import ParameterEventHandler  # noqa: E402
from harness.proc import Proc, python_module  # noqa: E402
from harness.ros import RosSession  # noqa: E402

BURST = 3


def run(runs: int, mode: str) -> dict:
    ros = RosSession()
    prefix = f'/filter_arrival_{uuid.uuid4().hex[:8]}'
    names = [f'{prefix}/{n}' for n in 'abc']
    argv = python_module('harness.param_nodes', *names)
    nodes = Proc('param_nodes', argv, guard.environment())
    short, waits = [], []
    try:
        assert nodes.wait_for('READY', 30), nodes.tail()
        for i in range(runs):
            handler = ParameterEventHandler(ros.node)
            handler.add_parameter_callback('value', names[0], lambda p: None)
            handler.add_parameter_event_callback(lambda e: None)
            assert nodes.request('matched 1', 'MATCHED') == 'MATCHED'
            if mode == 'wait':
                start = time.monotonic()
                assert handler.wait_for_filter(30.0), f'run {i}: not proven within 30 s'
                waits.append(time.monotonic() - start)
            before = handler.parameter_event_filter_state.events_received
            nodes.request(f'burst {BURST}', 'BURST')
            expected = BURST * len(names)
            ros.spin_until(lambda handler=handler, before=before, expected=expected:
                           handler.parameter_event_filter_state.events_received - before
                           >= expected, 5.0)
            received = handler.parameter_event_filter_state.events_received - before
            if received < expected:
                short.append({'run': i, 'received': received})
            handler.destroy()
    finally:
        nodes.stop()
        ros.close()
    result = {'mode': mode, 'runs': runs, 'expected_per_run': BURST * len(names),
              'short_runs': len(short), 'short': short}
    if waits:
        waits.sort()
        result['wait_for_filter_s'] = {'min': waits[0], 'median': waits[len(waits) // 2],
                                       'max': waits[-1]}
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--runs', type=int, default=60)
    parser.add_argument('--mode', choices=('burst', 'wait'), default='burst')
    args = parser.parse_args()
    result = run(args.runs, args.mode)
    print(json.dumps(result, indent=1))
    out = REPO / 'benchmarks' / 'results' / (
        f'filter-arrival-{args.mode}-{datetime.date.today()}-{platform.node()}.json')
    out.write_text(json.dumps(result, indent=1) + '\n')
    print(f'written to {out}')


if __name__ == '__main__':
    main()
