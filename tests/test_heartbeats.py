"""A guarded writer with rclpy's default feedback depth sends filtered readers no datagram per
sample that is not theirs (cft_action/_guard_heartbeats.c).

A keep-last-10 writer's history is nearly always full, and Fast DDS 2.14 then heartbeats every
reader at each write: a filtered reader, which gets none of the DATA, receives a HEARTBEAT of its
own per write. The guard lets that HEARTBEAT to all readers through at most once per
``CFT_GUARD_HEARTBEAT_ALL_MS`` per writer; otherwise it goes with the DATA to the DATA's readers.
On the wire (UDP only, captured on loopback as in tests/test_signatures.py): each filtered reader
gets no more lone HEARTBEATs than the guard let through, and exactly its own feedback; the plain
reader beside them gets every sample.
"""

from __future__ import annotations

import json
import os
import threading

import pytest

from cft_action import guard
from harness.capture import writer_datagrams_by_port
from harness.ros import unique_name
from tests.support import action_server, helper_process
from tests.test_signatures import UDP_ONLY

GOALS, ORDER = 4, 50
#: Lone HEARTBEATs a filtered reader may get besides the ones the guard let through to all
#: readers: the periodic heartbeat (every 3 s), and replies to its acknowledgements.
SLACK = 20

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason='a raw socket needs root')


def test_a_full_history_heartbeats_filtered_readers_only_as_often_as_the_guard_lets_it() -> None:
    env = {**os.environ, **UDP_ONLY}
    action = '/' + unique_name('cft_heartbeats')
    server = action_server(action, 0.01, env=guard.environment(env), feedback_depth=10)
    stop, listening = threading.Event(), threading.Event()
    captured: dict = {}
    processes = []
    sniffer = None
    try:
        stats = server.request_json('stats', 'STATS')
        writer = bytes.fromhex(stats['writers']['feedback'][0])
        # Each client proves its feedback path before READY; the capture starts after that.
        processes = [helper_process('tests.helpers.fib_client',
                                    [action, mode, GOALS, ORDER, 'guarded'], env=env)
                     for mode in ('client', 'client', 'rclpy')]
        sniffer = threading.Thread(target=lambda: captured.update(
            writer_datagrams_by_port('lo', {writer}, stop, listening)))
        sniffer.start()
        assert listening.wait(10)
        before = server.request_json('stats', 'STATS')['guard_heartbeats']
        for process in processes:
            process.send('go')
        reports = [json.loads(process.expect('RESULT', timeout=90).split(' ', 1)[1])
                   for process in processes]
        after = server.request_json('stats', 'STATS')['guard_heartbeats']
        assert server.poll() is None, f'server died\n{server.tail()}'
    finally:
        stop.set()
        if sniffer is not None:
            sniffer.join(timeout=10)
        for process in processes:
            process.stop()
        server.stop()
    for report in reports:
        assert report['misrouted'] == 0, report
    counts = {k: after[k] - before[k] for k in after}
    assert counts['narrowed'] > 0, counts  # the history was full, and the guard narrowed it
    # The port of each client's participant: the plain one got DATA for every write.
    writes = GOALS * ORDER * len(processes)
    by_data = sorted(captured.items(), key=lambda item: item[1]['data'])
    *filtered, (_, plain) = by_data
    assert len(filtered) == 2, captured
    assert plain['data'] >= writes, captured
    for _, datagrams in filtered:
        assert datagrams['data'] <= GOALS * ORDER + SLACK, captured  # own samples, and repairs
        assert datagrams['heartbeat'] <= counts['widened'] + SLACK, (captured, counts)
