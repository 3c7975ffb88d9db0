"""The library's own filter class, CFT_ACTION_UUID (cft_action/native/_filter_class.c).

A client's feedback filter uses it, so that only a guarded server's writer filters: an unguarded
server does not know the class, sends every sample, and the client's reader drops foreign ones.
"""

import ctypes
import os
import random

from types import SimpleNamespace

import pytest
from test_msgs.action import Fibonacci

from cft_action import _native, _rcl, ActionClient
from cft_action.action.goal_filter import GoalFilterPlan, TAG_BYTES
from harness.ros import unique_name
from tests.support import fastdds_header_probe, result_of, send
from tests.test_action_client import make_client, start_server

ORDER = 10


def library():
    lib = ctypes.CDLL(_native.extension_path(_native.READER_LOCK_LIBRARY))
    lib.cft_uuid_filter_try.restype = ctypes.c_int
    lib.cft_uuid_filter_try.argtypes = [ctypes.c_char_p, ctypes.c_void_p, ctypes.c_int,
                                        ctypes.c_char_p]
    return lib


def verdict(lib, expression, uuid):
    return lib.cft_uuid_filter_try(expression.encode(), None, 0, bytes(uuid))


def near(uuid, shared):
    """A random UUID whose first ``shared`` bytes are those of ``uuid`` and the next one differs."""
    raw = bytearray(os.urandom(16))
    raw[:shared] = uuid[:shared]
    raw[shared] = (uuid[shared] + random.randint(1, 255)) % 256
    return bytes(raw)


@pytest.mark.parametrize('mode', ['client', 'goals'])
def test_verdicts_are_exact_over_random_uuids_and_tag_collisions(mode):
    """The class gives the plan's verdict for every goal filter: exactly the UUIDs that start
    with the tag or with a live goal's term, including UUIDs sharing 1, 2 or 3 bytes with them."""
    lib = library()
    rng = random.Random(7)
    plan = GoalFilterPlan(mode, new_uuid=lambda: rng.randbytes(16))
    plan.initial()
    supplied = [rng.randbytes(16) for _ in range(5)]
    generated = [plan.uuid_for_feedback() for _ in range(5)]
    for goal in supplied + generated:
        plan.watch(goal)
    expression = plan.grow()
    prefixes = ([plan.tag] if plan.tag else []) + [g if g in supplied else g[:4]
                                                    for g in supplied + generated]
    candidates = [rng.randbytes(16) for _ in range(2000)]
    for prefix in prefixes:
        candidates += [prefix + rng.randbytes(16 - len(prefix))]
        candidates += [near(prefix, shared) for shared in (1, 2, 3) for _ in range(50)]
    assert plan.tag is None or len(plan.tag) == TAG_BYTES
    for uuid in candidates:
        expected = any(uuid.startswith(p) for p in prefixes)
        assert verdict(lib, expression, uuid) == int(expected), (expression, uuid.hex())


def test_expressions_outside_the_grammar_are_refused():
    lib = library()
    for expression in ['data = 1', 'goal_id.uuid[0] = %0', 'goal_id.uuid[16] = 1',
                       'goal_id.uuid[0] = 256', 'goal_id.uuid[0] = 1 AND goal_id.uuid[1] = 2 OR '
                       'goal_id.uuid[2] = 3', 'goal_id.uuid[0] > 1']:
        assert verdict(lib, expression, bytes(16)) == -1, expression


PROBE = r'''
#include <cstdio>
#include <cstring>
#include <type_traits>
#include <fastdds/dds/topic/IContentFilterFactory.hpp>
#include <fastdds/rtps/common/SerializedPayload.h>
using namespace eprosima::fastdds::dds;
template <class M> long slot(M m) { long raw; std::memcpy(&raw, &m, sizeof raw); return raw; }
int main() {
  // Itanium ABI: a pointer to a virtual member is 1 + its byte offset in the vtable.
  std::printf("%ld %ld %ld\n", slot(&IContentFilterFactory::create_content_filter),
              slot(&IContentFilterFactory::delete_content_filter), slot(&IContentFilter::evaluate));
  std::printf("%zu %zu\n", sizeof(IContentFilterFactory), sizeof(IContentFilter));
  using RC = IContentFilterFactory::ReturnCode_t;
  std::printf("%zu %d\n", sizeof(RC), (int)std::is_trivially_copyable<RC>::value);
  std::printf("%zu %zu\n", offsetof(eprosima::fastrtps::rtps::SerializedPayload_t, length),
              offsetof(eprosima::fastrtps::rtps::SerializedPayload_t, data));
}
'''


def test_the_c_objects_match_the_fastdds_interfaces(tmp_path):
    """_filter_class.c builds the two interfaces' vtables by hand: slots 0 and 1 of the factory,
    slot 0 of the filter, no virtual destructor, ReturnCode_t in a register, payload fields."""
    assert fastdds_header_probe(PROBE, tmp_path) == [1, 9, 1, 8, 8, 4, 1, 4, 8]


def own_and_foreign_goal(ros, child, action):
    """One goal of a default client and one of a plain one; returns the default client and its
    feedback filter state from before those goals, with its reader's verdicts then as
    ``before.reader_verdicts``."""
    ours = make_client(ros, action)
    before = SimpleNamespace(**ours.feedback_filter_state._asdict(),
                             reader_verdicts=ours._reader.reader_verdicts)
    other = ActionClient(ros.node, Fibonacci, action, feedback_filter='off')
    assert other.wait_for_server(timeout_sec=20)
    foreign = send(ros, other, ORDER, feedback_callback=lambda _: None)
    own = send(ros, ours, ORDER, feedback_callback=lambda _: None)
    result_of(ros, foreign)
    result_of(ros, own)
    assert ros.spin_until(
        lambda: ours.feedback_filter_state.feedback_taken - before.feedback_taken == ORDER, 10)
    ros.spin_for(0.5)
    assert child.poll() is None, f'server died\n{child.tail()}'
    return ours, before


@pytest.mark.parametrize('guarded', [False, True], ids=['unguarded', 'guarded'])
def test_where_other_goals_feedback_is_dropped(ros, guarded):
    """An unguarded server sends everything: the client's reader judges every sample itself and
    only its own goals' feedback reaches rcl. A guarded one filters in its writer, and its
    samples carry no filter signature: the reader judges its own goals' feedback only, and knows
    where the rest was dropped from the writer's discovery data."""
    action = '/' + unique_name('fib')
    child = start_server(action, guarded=guarded)
    try:
        ours, before = own_and_foreign_goal(ros, child, action)
        state = ours.feedback_filter_state
        assert state.active and state.feedback_taken - before.feedback_taken == ORDER, state
        assert state.feedback_dropped == before.feedback_dropped, state
        if guarded:
            assert state.filtered_in == 'writer', state
            assert ours._reader.reader_verdicts - before.reader_verdicts == ORDER, state
            counts = child.request_json('stats', 'STATS')['guard_filter_class']
            # The writer keeps the reader in the guard's table: no filter of the class there.
            assert counts['filters'] == 0 and counts['verdicts'] == 0, counts
            kept = child.request_json('stats', 'STATS')['guard_filter']
            assert kept['kept'] >= 1 and kept['relevance_verdicts'] >= 2 * ORDER, kept
        else:
            # Both goals' feedback came over the wire, and the reader judged every sample.
            assert state.filtered_in == 'reader', state
            assert ours._reader.reader_verdicts - before.reader_verdicts >= 2 * ORDER, state
    finally:
        child.stop()


def test_writer_filtering_any_keeps_dds_sql(ros):
    action = '/' + unique_name('fib')
    child = start_server(action, guarded=True)
    try:
        client = make_client(ros, action, writer_filtering='any')
        assert not client._reader.filter_class
        assert client.feedback_filter_state.filtered_in == 'writer'
        counts = child.request_json('stats', 'STATS')['guard_filter_class']
        assert counts['filters'] == 0, counts
    finally:
        child.stop()


def test_the_class_is_installed_in_this_process():
    assert _rcl.filter_class_status() == ''
