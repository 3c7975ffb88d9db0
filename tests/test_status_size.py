"""The status topic's size model (:mod:`harness.status_model`, which ``benchmarks/status.py`` uses):
serialized ``GoalStatusArray`` sizes, and the wire model built on them, against rclpy's own
serialization and captured frames."""

from __future__ import annotations

import pytest
from action_msgs.msg import GoalStatus, GoalStatusArray
from rclpy.serialization import serialize_message

from harness.status_model import entries_in, predict, status_array_size, wire_bytes


@pytest.mark.parametrize('entries', [0, 1, 2, 3, 64, 513])
def test_status_array_size_is_the_serialized_size(entries):
    message = GoalStatusArray(status_list=[GoalStatus() for _ in range(entries)])
    assert status_array_size(entries) == len(serialize_message(message))


def test_wire_model_matches_the_captured_frames_and_inverts():
    # Frames captured on a client's veth (benchmarks.status smoke runs, 2026-12-02): one reader,
    # 1 to 4 entries: 242, 270, 298, 326 bytes; two readers, 1 entry: 226.
    assert [wire_bytes(n, readers=1) for n in (1, 2, 3, 4)] == [242, 270, 298, 326]
    assert wire_bytes(1, readers=2) == 226
    for readers in (1, 2):
        for n in (1, 12, 40):  # one frame: the UDP datagram is the frame less Ethernet and IPv4
            assert entries_in(wire_bytes(n, readers) - 14 - 20, readers) == n
    # 500 entries: a 14 198-byte frame's IPv4 payload in 10 fragments, 9 more headers of 34 bytes.
    assert wire_bytes(500, readers=2) == 14198 + 9 * 34


def test_a_batch_of_goals_costs_two_g_squared_plus_g_entries():
    for goals in (1, 4, 64):
        model = predict([0.0] * goals, duration_s=1.0, result_timeout_s=2.0)
        assert model['messages'] == 3 * goals
        assert model['entries'] == 2 * goals ** 2 + goals
        assert model['max_entries'] == goals
