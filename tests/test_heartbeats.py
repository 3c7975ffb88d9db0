"""A guarded writer with rclpy's default feedback depth sends filtered readers no datagram per
sample that is not theirs (cft_action/native/guard/_guard_heartbeats.c).

A keep-last-10 writer's history is nearly always full, and Fast DDS 2.14 then heartbeats every
reader at each write: a filtered reader, which gets none of the DATA, receives a HEARTBEAT of its
own per write. The guard keeps that HEARTBEAT with the DATA, to the DATA's readers
(``CFT_GUARD_HEARTBEAT_ALL_MS``, default ``never``; a status writer's every 10 ms), and in a
write that judged a kept reader and a plain one sends that HEARTBEAT at most every 10 ms
(``CFT_GUARD_PIGGYBACK_MS``). With filtered readers only, the personal GAP and HEARTBEAT that
Fast DDS sends a reader in a datagram of their own before its DATA, after others' samples, go in
the DATA's datagram (``CFT_GUARD_MERGE_GAPS``).
On the wire (UDP only, captured on loopback as in tests/test_signatures.py): each filtered reader
gets no more lone HEARTBEATs than the guard let through, and exactly its own feedback; the plain
reader beside them gets every sample.
"""

from __future__ import annotations

import os

import pytest

from harness.capture import writer_datagrams_by_port
from tests.support import feedback_on_the_wire

GOALS, ORDER = 4, 50
#: Lone HEARTBEATs a filtered reader may get besides the ones the guard let through to all
#: readers: the periodic heartbeat (every 3 s), and replies to its acknowledgements.
SLACK = 20

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason='a raw socket needs root')


def test_a_full_history_sends_filtered_readers_no_heartbeat_per_foreign_write() -> None:
    clients = [('client', 'guarded'), ('client', 'guarded'), ('rclpy', 'guarded')]
    run = feedback_on_the_wire(clients, writer_datagrams_by_port, GOALS, ORDER, feedback_depth=10)
    for report in run.reports:
        assert report['misrouted'] == 0, report
    counts = run.counted('guard_heartbeats')
    assert counts['narrowed'] > 0, counts  # the history was full, and the guard narrowed it
    assert counts['piggyback_spaced'] > 0, counts  # writes within 10 ms of a HEARTBEAT sent none
    # Each feedback write goes to the plain reader too: only replies, each to its requester
    # alone (goal and result, per goal), carry their reader's GAP in their DATA.
    assert counts['gaps_merged'] <= 2 * GOALS * len(clients), counts
    # The port of each client's participant: the plain one got DATA for every write.
    captured = run.captured
    writes = GOALS * ORDER * len(clients)
    by_data = sorted(captured.items(), key=lambda item: item[1]['data'])
    *filtered, (_, plain) = by_data
    assert len(filtered) == 2, captured
    assert plain['data'] >= writes, captured
    for _, datagrams in filtered:
        assert datagrams['data'] <= GOALS * ORDER + SLACK, captured  # own samples, and repairs
        # never widened for the feedback writer (the status writer's widenings are in the counts)
        assert datagrams['heartbeat'] <= SLACK, (captured, counts)
        # beside the plain reader the personal GAPs come alone (CFT_GUARD_MERGE_GAPS=0 everywhere)
        assert datagrams['gap+heartbeat'] > SLACK, (captured, counts)


def test_filtered_readers_get_their_personal_gap_in_their_data() -> None:
    """Two filtered clients alone on the writer: each one's sample after the other's follows a run
    of changes filtered out for it, which Fast DDS closes with a personal GAP and HEARTBEAT in a
    datagram of their own before the DATA. The guard puts them in the DATA's datagram (beside a
    plain reader they come alone, as the test above sees)."""
    clients = [('client', 'guarded'), ('client', 'guarded')]
    run = feedback_on_the_wire(clients, writer_datagrams_by_port, GOALS, ORDER, feedback_depth=10)
    for report in run.reports:
        assert report['complete_goals'] == GOALS and report['misrouted'] == 0, report
    counts = run.counted('guard_heartbeats')
    assert counts['merges_dropped'] == 0 and counts['gaps_merged'] > 0, counts
    # a full history's piggyback HEARTBEAT after a merged one would repeat it
    assert counts['piggyback_merged'] > 0, counts
    assert len(run.captured) == 2, run.captured
    for datagrams in run.captured.values():
        assert datagrams['data'] <= GOALS * ORDER + SLACK, run.captured
        # only the periodic heartbeat's (2.14.6 sends a reader's GAP with it)
        assert datagrams['gap'] + datagrams['gap+heartbeat'] <= SLACK, (run.captured, counts)
