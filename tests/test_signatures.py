"""Filter signatures on the wire: a guarded server writes none for the library's filter classes.

Fast DDS 2.14 puts ``PID_CONTENT_FILTER_INFO`` (16 bytes of signature per reader in its writer's
filter collection) into every DATA of a writer with filtered readers, to every reader. The guard
keeps the readers of the library's classes out of that collection and answers for them itself
(cft_action/native/guard/_guard_filter.c, "readers the guard keeps itself"): their feedback DATA
must carry no signature, the writer must still send each of them only its own goals' feedback, and a
DDS-SQL filter (``writer_filtering='any'``) must keep Fast DDS's behaviour, signature included.

The server and its clients run in processes of their own on UDP only
(``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` with ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``: with
``LOCALHOST`` rmw_fastrtps adds shared memory, which carries the data past any capture), in this
session's domain. Datagrams between local addresses pass the loopback interface, where a raw
socket (root) reads the feedback writer's DATA submessages (:func:`harness.capture.data_by_port`).
"""

from __future__ import annotations

import os

import pytest

from cft_action import _rcl
from harness.capture import data_by_port
from harness.proc import stop_all
from harness.ros import unique_name
from tests.support import feedback_on_the_wire
from tests.test_action_client import start_server

GOALS, ORDER = 2, 20
pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason='a raw socket needs root')


def data_on_the_wire(clients: list[tuple[str, str]], server_env: dict[str, str]):
    """The clients' reports, and the feedback writer's DATA by destination port."""
    run = feedback_on_the_wire(clients, data_by_port, GOALS, ORDER, server_env=server_env)
    return run.reports, run.captured


def assert_own_feedback_only(reports, captured, filtered: int) -> None:
    """Each client took its goals' feedback whole; of the ports the writer sent DATA to, one per
    filtered client got exactly its own samples, and the plain one got every sample."""
    for report in reports:
        assert report['complete_goals'] == GOALS and report['misrouted'] == 0, report
    every = GOALS * ORDER * len(reports)
    assert sorted(len(samples) for samples in captured.values()) == (
        [GOALS * ORDER] * filtered + [every]), {p: len(s) for p, s in captured.items()}


def test_no_signature_for_the_library_classes() -> None:
    """Two clients of each mode and a plain one, on one server."""
    reports, captured = data_on_the_wire([('client', 'guarded'), ('client', 'guarded'),
                                              ('goals', 'guarded'), ('goals', 'guarded'),
                                              ('rclpy', 'guarded')], {})
    assert_own_feedback_only(reports, captured, filtered=4)
    carried = {p: sum(s is not None for s in samples.values()) for p, samples in captured.items()}
    assert set(carried.values()) == {0}, carried
    for report in reports[:4]:
        # The reader judged the samples that reached it: its own goals' only. It knows where the
        # others were dropped from the writer's discovery data, not from a signature.
        assert (report['reader_verdicts'] - report['proof_verdicts']
                == report['taken'] - report['proof_taken'] == GOALS * ORDER), report
        assert report['filtered_in'] == 'writer', report


def test_a_dds_sql_filter_keeps_its_signature() -> None:
    """Beside a reader of the library's class, a DDS-SQL reader is Fast DDS's: every DATA, to
    every reader, carries exactly its one signature."""
    reports, captured = data_on_the_wire([('client', 'any'), ('client', 'guarded'),
                                              ('rclpy', 'guarded')], {})
    assert_own_feedback_only(reports, captured, filtered=2)
    signatures = {s for samples in captured.values() for s in samples.values()}
    assert signatures == {1}, signatures


def test_fastdds_signatures_when_the_guard_leaves_the_readers_to_it() -> None:
    """``CFT_GUARD_KEEP_READERS=0`` (the benchmarks' comparison): Fast DDS keeps the readers of
    the library's class, and every DATA carries both their signatures, as before the guard kept
    them. The capture would see a signature if there were one."""
    reports, captured = data_on_the_wire([('client', 'guarded'), ('client', 'guarded'),
                                              ('rclpy', 'guarded')],
                                             {'CFT_GUARD_KEEP_READERS': '0'})
    assert_own_feedback_only(reports, captured, filtered=2)
    signatures = {s for samples in captured.values() for s in samples.values()}
    assert signatures == {2}, signatures


def test_only_a_guarded_writer_says_it_filters_in_its_discovery_data(ros) -> None:
    """The mark in USER_DATA (cft_action/native/guard/_guard_writer_qos.c), as this process reads it
    (cft_action/native/reader/_writer_marks.c): on a guarded server's feedback writer, not on a
    plain one's. The GID that rclpy reports is the 16 bytes the mark is recorded under."""
    servers = {}
    for guarded in (True, False):
        action = '/' + unique_name('cft_mark')
        servers[guarded] = (action, start_server(action, guarded=guarded))
    try:
        for guarded, (action, child) in servers.items():
            topic = f'{action}/_action/feedback'
            assert ros.spin_until(lambda t=topic: ros.node.get_publishers_info_by_topic(t), 20)
            [writer] = ros.node.get_publishers_info_by_topic(topic)
            assert len(writer.endpoint_gid) == 16
            assert _rcl.writer_filters(bytes(writer.endpoint_gid)) is guarded, action
            marked = child.request_json('stats', 'STATS').get('guard_writers', {})
            assert (marked.get('marked', 0) > 0) is guarded, marked
    finally:
        stop_all(child for _, child in servers.values())
