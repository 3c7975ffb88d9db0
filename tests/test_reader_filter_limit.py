"""Past 32 filtered readers: the guard raises a writer's limit, so the server filters for each one.

A Fast DDS 2.14 writer filters for at most 32 readers of its filter collection; the others receive
every sample. The server's guard counts the filter evaluations, one per sample and filtered reader,
so evaluations per published sample is how many readers the feedback writer filters for. The
guard keeps the readers of the library's classes out of that collection (docs/INTERNALS.md section
18), so they are not limited at all; the limit is measured with ``CFT_GUARD_KEEP_READERS=0``, where
Fast DDS's collection holds them as it holds a DDS-SQL reader.
"""

import ctypes
import json
import os

import pytest
import rclpy.action
from test_msgs.action import Fibonacci

from cft_action import ActionClient, guard
from harness.ros import unique_name
from tests.support import (action_server, fastdds_header_probe, prove_feedback_path, round_trip,
                           server_evidence)

READERS = 40
ORDER = 5


def evaluations(stats: dict, kept: bool) -> int:
    """The server's verdicts on the clients' filters (of the library's class): the guard's own for
    readers it keeps, else those of the class's filters in Fast DDS's collection."""
    if kept:  # the feedback readers' (status readers are kept too: their verdicts apart)
        return stats['guard_filter']['relevance_verdicts'] - stats['guard_status']['verdicts']
    return stats['guard_filter_class']['verdicts']


@pytest.mark.parametrize('limit, kept, filtered_for',
                         [(None, False, READERS), ('32', False, 32), ('32', True, READERS)],
                         ids=['guard-default', 'fastdds-limit', 'kept-readers-past-the-limit'])
def test_a_guarded_writer_filters_for_every_client_past_32(ros, limit, kept, filtered_for):
    env = guard.environment()
    if limit is not None:
        env[guard.READER_FILTERS_ENV] = limit
    if not kept:
        env['CFT_GUARD_KEEP_READERS'] = '0'
    action = '/' + unique_name('cft_limit')
    server = action_server(action, 0.02, env=env)
    clients = [ActionClient(ros.node, Fibonacci, action) for _ in range(READERS)]
    # Created after the filtered readers: its answer proves that the server has processed their
    # discovery, which comes from this participant in one ordered stream. Its first goals may go
    # unanswered while the server is busy with that discovery (round_trip).
    witness = rclpy.action.ActionClient(ros.node, Fibonacci, action)
    try:
        assert witness.wait_for_server(timeout_sec=30)
        assert round_trip(ros, witness, tries=15), server_evidence(server)
        prove_feedback_path(ros.spin_until, clients[0])
        before = server.request_json('stats', 'STATS')
        received = []
        goal = clients[0].send_goal_async(Fibonacci.Goal(order=ORDER),
                                          feedback_callback=received.append)
        assert ros.spin_until(lambda: len(received) >= ORDER, timeout=30), received
        after = server.request_json('stats', 'STATS')
        published = after['published'] - before['published']
        assert published >= ORDER
        assert evaluations(after, kept) - evaluations(before, kept) == filtered_for * published, (
            json.dumps(after['guard_filter']), after['guard_filter_class'])
        if kept:  # none of them in Fast DDS's collection, whatever its limit
            assert after['guard_filter']['kept'] >= READERS and after['guard_filter']['left'] == 0
        writers = after['guard_writers']
        assert writers['reader_filters'] == (1024 if limit is None else 32), writers
        assert (writers['raised'] > 0) == (limit is None) and writers['left'] == 0, writers
        assert goal.done() and all(c.feedback_filter_state.active for c in clients)
    finally:
        for client in (*clients, witness):
            client.destroy()
        server.stop()
    assert os.environ.get(guard.READER_FILTERS_ENV) is None, 'the suite must not set it'


WRITER_QOS_PROBE = r'''
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <cstdio>
using eprosima::fastdds::dds::DataWriterQos;
int main() {
  alignas(DataWriterQos) static char storage[sizeof(DataWriterQos)];
  auto* qos = reinterpret_cast<DataWriterQos*>(storage);  // inline accessors only
  const auto& config = qos->writer_resource_limits().reader_filters_allocation;
  printf("%td\n", reinterpret_cast<const char*>(&config) - storage);
  static_assert(sizeof(config) == 3 * sizeof(size_t), "initial, maximum, increment");
  return 0;
}
'''


def test_the_writer_qos_offset_is_that_of_the_installed_fast_dds_headers(tmp_path):
    headers = fastdds_header_probe(WRITER_QOS_PROBE, tmp_path)
    library = ctypes.CDLL(guard.library_path(), mode=os.RTLD_LOCAL)
    library.cft_guard_writer_qos_layout.restype = ctypes.c_long
    assert [library.cft_guard_writer_qos_layout(i) for i in range(len(headers))] == headers
    assert library.cft_guard_writer_qos_layout(len(headers)) == -1


def test_an_unusable_limit_keeps_fastdds_32_and_says_so(ros):
    env = {**guard.environment(), guard.READER_FILTERS_ENV: '64k'}
    server = action_server('/' + unique_name('cft_limit_bad'), 0.02, env=env)
    try:
        writers = server.request_json('stats', 'STATS')['guard_writers']
        assert {k: writers[k] for k in ('raised', 'left', 'reader_filters')} == {
            'raised': 0, 'left': 0, 'reader_filters': 32}, writers
    finally:
        server.stop()
    assert 'CFT_ACTION_READER_FILTERS=64k is not a number from 1 to 4063' in server.tail()
