"""The status trim: a status sample reaches Python with only the entries of the client's own goals,
and every goal handle sees the statuses that plain rclpy would give it.

The trim itself (cft_action/native/reader/_status_trim.c) is checked against rclpy's own serializer;
the client is checked against a shadow of rclpy's rule, applied at every ``execute`` to the whole
sample that the trim read, while clients in another process keep the server busy with their goals.
"""

from __future__ import annotations

import ctypes
import os
import random
import struct
from typing import Any

import pytest
from action_msgs.msg import GoalInfo, GoalStatus, GoalStatusArray
from builtin_interfaces.msg import Time
from rclpy.qos import qos_profile_action_status_default, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from test_msgs.action import Fibonacci
from unique_identifier_msgs.msg import UUID

from cft_action import _rcl, ActionClient
from cft_action.action.goal_filter import MODES
from harness.ros import unique_name
from tests.support import helper_process, round_trip
from tests.test_action_client import start_server

_TERMINAL = (GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED, GoalStatus.STATUS_ABORTED)


def entry(goal_uuid: bytes, status: int, sec: int = 0, nanosec: int = 0) -> GoalStatus:
    return GoalStatus(goal_info=GoalInfo(goal_id=UUID(uuid=list(goal_uuid)),
                                         stamp=Time(sec=sec, nanosec=nanosec)), status=status)


class Table:
    """cft_action/native/reader/_status_trim.c's table, driven directly."""

    def __init__(self) -> None:
        self.table = _rcl._lib.cft_status_table_new()

    def sending(self, goal_uuid: bytes) -> None:
        assert _rcl._lib.cft_status_table_sending(self.table, goal_uuid) == 0

    def responded(self, goal_uuid: bytes, accepted: bool) -> int:
        return _rcl._lib.cft_status_table_responded(self.table, goal_uuid, int(accepted))

    def trim(self, sample: bytes, responding: bytes | None = None,
             all_pending: bool = True) -> tuple[int, bytes]:
        out = ctypes.create_string_buffer(max(1, len(sample)))
        length = ctypes.c_size_t(0)
        entries = _rcl._lib.cft_status_trim(self.table, sample, len(sample), out,
                                            ctypes.byref(length), responding, int(all_pending))
        return entries, out.raw[:length.value]

    def delivered(self, entries: list[GoalStatus], responding: bytes | None = None,
                  all_pending: bool = True) -> list[GoalStatus]:
        count, cdr = self.trim(serialize_message(GoalStatusArray(status_list=entries)),
                               responding, all_pending)
        message = deserialize_message(cdr, GoalStatusArray)
        assert len(message.status_list) == count
        return list(message.status_list)

    def __del__(self) -> None:
        _rcl._lib.cft_status_table_free(self.table)


def big_endian(message: GoalStatusArray) -> bytes:
    """The message in big-endian CDR (encapsulation 0x0000), written by hand."""
    body = struct.pack('>I', len(message.status_list))
    for status in message.status_list:
        body += bytes(status.goal_info.goal_id.uuid)
        body += b'\0' * (-len(body) % 4)
        body += struct.pack('>iIb', status.goal_info.stamp.sec, status.goal_info.stamp.nanosec,
                            status.status)
    return b'\x00\x00\x00\x00' + body


def test_the_trim_keeps_exactly_the_pending_goals_entries_in_order():
    """Random arrays, with every field at random, little endian as rmw_fastrtps writes them and
    big endian: the trimmed array is the sub-list of the own goals, byte-exact in length."""
    rng = random.Random(26)
    for _ in range(300):
        goals = [rng.randbytes(16) for _ in range(rng.randint(0, 60))]
        own = {u for u in goals if rng.random() < 0.3}
        table = Table()
        for goal_uuid in own:
            table.sending(goal_uuid)
        message = GoalStatusArray(status_list=[
            entry(u, rng.randint(0, 6), rng.randint(-2**31, 2**31 - 1), rng.randint(0, 2**32 - 1))
            for u in goals])
        wanted = [s for s in message.status_list if bytes(s.goal_info.goal_id.uuid) in own]
        for sample in (serialize_message(message), big_endian(message)):
            count, cdr = table.trim(sample)
            assert count == len(wanted)
            assert list(deserialize_message(cdr, GoalStatusArray).status_list) == wanted
            assert len(cdr) == len(serialize_message(GoalStatusArray(status_list=wanted)))


def test_an_entry_takes_25_bytes_then_28():
    """CDR aligns each stamp to 4 bytes from the body's start: the uuid of the first entry starts
    at 4, every later one 3 bytes past a multiple of 4 (docs/INTERNALS.md)."""
    sizes = [len(serialize_message(GoalStatusArray(status_list=[entry(os.urandom(16), 1)] * n)))
             for n in range(5)]
    assert sizes == [8, 33, 61, 89, 117]


def test_a_sample_that_is_not_plain_cdr_is_refused_whole():
    table = Table()
    goal_uuid = os.urandom(16)
    table.sending(goal_uuid)
    sample = serialize_message(GoalStatusArray(status_list=[entry(goal_uuid, 1)] * 3))
    assert table.trim(sample[:-1])[0] == -1  # truncated
    assert table.trim(b'\x00\x07' + sample[2:])[0] == -1  # XCDR2 encapsulation
    assert table.trim(b'')[0] == -1
    huge = sample[:4] + struct.pack('<I', 2**32 - 1) + sample[8:]
    assert table.trim(huge)[0] == -1


def test_an_accepted_goal_gets_its_first_entry_and_each_change_once():
    """Pending (request sent, response not executed): only with its own response, which rclpy's
    execute turns into a handle before it reads the status, or with a response of an unknown goal.
    Accepted: the first entry, then only changes; after a terminal one, none. Rejected: none.
    Others' goals: never."""
    table = Table()
    mine, rejected, other = os.urandom(16), os.urandom(16), os.urandom(16)
    table.sending(mine)
    table.sending(rejected)
    executing = [entry(mine, GoalStatus.STATUS_EXECUTING), entry(other, 1),
                 entry(rejected, GoalStatus.STATUS_EXECUTING)]
    assert table.responded(mine, True) == -1  # no sample listed it: no early status
    assert table.responded(rejected, False) == -1
    assert table.delivered(executing) == [executing[0]]
    assert table.delivered(executing) == []
    succeeded = [entry(other, 4), entry(mine, GoalStatus.STATUS_SUCCEEDED)]
    assert table.delivered(succeeded) == [succeeded[1]]
    assert table.delivered(succeeded) == []
    assert table.responded(mine, True) == -1  # a late duplicate response changes nothing
    assert table.delivered(succeeded) == []
    assert _rcl._lib.cft_status_table_count(table.table, 3) == 0


def test_a_status_that_came_before_the_response_goes_to_the_new_handle():
    """A sample that lists a pending goal without its response updates no handle in rclpy; the
    table keeps the last such status and hands it over when the goal is accepted (the client
    gives it to rclpy's execute then), after which only changes from it go. A terminal one ends
    the goal in the table; a rejected goal has none."""
    table = Table()
    mine, done, rejected = os.urandom(16), os.urandom(16), os.urandom(16)
    for goal_uuid in (mine, done, rejected):
        table.sending(goal_uuid)
    first = [entry(mine, GoalStatus.STATUS_ACCEPTED), entry(done, GoalStatus.STATUS_EXECUTING),
             entry(rejected, GoalStatus.STATUS_ACCEPTED)]
    later = [entry(mine, GoalStatus.STATUS_EXECUTING), entry(done, GoalStatus.STATUS_SUCCEEDED)]
    assert table.delivered(first, all_pending=False) == []
    assert table.delivered(later, all_pending=False) == []
    assert table.delivered(first, mine, all_pending=False) == [first[0]]  # an older one, with
    assert table.delivered(later, mine, all_pending=False) == [later[0]]  # mine's response
    assert table.responded(mine, True) == GoalStatus.STATUS_EXECUTING
    assert table.delivered(later, all_pending=False) == []  # the handle has it
    assert table.delivered([entry(mine, GoalStatus.STATUS_SUCCEEDED)]) != []
    assert table.responded(done, True) == GoalStatus.STATUS_SUCCEEDED
    assert table.responded(rejected, False) == -1
    assert _rcl._lib.cft_status_table_count(table.table, 3) == 0


def test_many_goals_come_and_go():
    """The table grows past its first size and shrinks back (deletion in linear probing)."""
    table = Table()
    goals = [os.urandom(16) for _ in range(3000)]
    for goal_uuid in goals:
        table.sending(goal_uuid)
        table.responded(goal_uuid, True)
    assert len(table.delivered([entry(u, 2) for u in goals])) == 3000
    ended = goals[::2]
    assert len(table.delivered([entry(u, 4) for u in ended])) == 1500
    left = table.delivered([entry(u, 3) for u in goals])
    assert {bytes(s.goal_info.goal_id.uuid) for s in left} == set(goals[1::2])
    assert _rcl._lib.cft_status_table_count(table.table, 3) == 1500


# --- the status subscription, and the fallback without it ----------------------------------------

def test_the_status_subscription_is_found_by_layout_and_a_wrong_name_refused(ros):
    client = ActionClient(ros.node, Fibonacci, 'status_layout', feedback_filter='off')
    pointer = client._client_handle.pointer
    found, reason = _rcl.action_subscription(
        pointer, ros.node.resolve_topic_name('status_layout'), 'status')
    assert found and reason == ''
    assert _rcl.subscription_topic_name(found) == '/status_layout/_action/status'
    missing, reason = _rcl.action_subscription(pointer, '/another_action', 'status')
    assert missing is None and 'layout check failed' in reason
    assert client.goal_status_state.active
    client.destroy()


def test_without_the_status_subscription_rclpy_takes_status_whole(ros, monkeypatch):
    found = _rcl.action_subscription
    monkeypatch.setattr(_rcl, 'action_subscription', lambda pointer, name, topic: (
        (None, 'layout check failed: forced by the test') if topic == 'status'
        else found(pointer, name, topic)))
    action = '/' + unique_name('fib')
    server = start_server(action, guarded=False)
    try:
        client = ActionClient(ros.node, Fibonacci, action)
        state = client.goal_status_state
        assert not state.active and 'forced by the test' in state.reason
        assert client.wait_for_server(timeout_sec=20)
        assert round_trip(ros, client), 'the server never answered a goal'
        future = client.send_goal_async(Fibonacci.Goal(order=2))
        assert ros.spin_until(future.done, 20)
        handle = future.result()
        assert ros.spin_until(lambda: handle.status == GoalStatus.STATUS_SUCCEEDED, 20)
        assert client.goal_status_state.samples == 0
    finally:
        server.stop()


# --- against a server, with other clients' goals --------------------------------------------------

class ShadowedClient(ActionClient):
    """The library's client, checked at every ``execute`` against plain rclpy's rule.

    The shadow is rclpy's status loop run on the whole sample that the trim read: a goal handle
    made in this execute starts UNKNOWN, then every entry of an existing, unfinished handle sets
    its status. One difference from rclpy, the library's: a handle starts with the status of the
    last sample that listed its goal before its response, if one did (rclpy's loop skipped that
    entry, as no handle existed yet). After each execute every goal handle must hold the shadow's
    status.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.handles: dict[bytes, Any] = {}
        self.shadow: dict[bytes, int] = {}  # goals whose handle exists and has not finished
        self.final: dict[bytes, int] = {}
        self.early: dict[bytes, int] = {}  # goals without a handle: their last listed status
        self.sequences: dict[bytes, list[int]] = {}
        self.mismatches: list[str] = []
        self.whole_entries = 0

    def take_data(self) -> dict:
        table = self._status._table
        before = table.counts()[0] if table is not None else 0
        data = super().take_data()
        if table is not None and table.counts()[0] > before:
            message = table._message  # the serialized sample that was just trimmed
            whole = deserialize_message(ctypes.string_at(message.buffer, message.buffer_length),
                                        GoalStatusArray)
            self.whole_entries += len(whole.status_list)
            data['whole status'] = whole
        return data

    async def execute(self, taken_data: dict) -> None:
        whole = taken_data.pop('whole status', None)
        goal = taken_data.get('goal')
        future = self._pending_goal_requests.get(goal[0]) if goal else None
        await super().execute(taken_data)
        if future is not None and future.done() and future.result().accepted:
            handle = future.result()
            goal_uuid = bytes(handle.goal_id.uuid)
            self.handles[goal_uuid] = handle
            self.shadow[goal_uuid] = self.early.pop(goal_uuid, GoalStatus.STATUS_UNKNOWN)
        for status in whole.status_list if whole is not None else []:
            goal_uuid = bytes(status.goal_info.goal_id.uuid)
            if goal_uuid not in self.handles:
                self.early[goal_uuid] = status.status
            elif goal_uuid in self.shadow:
                self.shadow[goal_uuid] = status.status
        for goal_uuid in [goal for goal, status in self.shadow.items() if status in _TERMINAL]:
            self.final[goal_uuid] = self.shadow.pop(goal_uuid)
        for goal_uuid, handle in self.handles.items():
            expected = self.shadow.get(goal_uuid, self.final.get(goal_uuid))
            if handle.status != expected:
                self.mismatches.append(f'{goal_uuid.hex()}: {handle.status}, rclpy {expected}')
            sequence = self.sequences.setdefault(goal_uuid, [])
            if not sequence or sequence[-1] != handle.status:
                sequence.append(handle.status)


def plain_status_subscription(ros: Any, action: str) -> list[GoalStatusArray]:
    """A plain rclpy subscription to the action's status, with the status QoS; the list holds its
    latest sample."""
    latest: list[GoalStatusArray] = []

    def keep(message: GoalStatusArray) -> None:
        latest[:] = [message]

    ros.node.create_subscription(GoalStatusArray, f'{action}/_action/status', keep,
                                 qos_profile_action_status_default)
    return latest


def server_done(server: Any, accepted: int) -> bool:
    """Whether the server accepted at least ``accepted`` goals and runs none."""
    stats = server.request_json('stats', 'STATS')
    return stats['accepted'] >= accepted and stats['active'] == 0


@pytest.mark.parametrize('guarded', [False, True], ids=['unguarded', 'guarded'])
@pytest.mark.parametrize('mode', MODES)
def test_every_goal_handle_sees_what_plain_rclpy_gives(ros, mode, guarded):
    """A plain client in another process runs 60 goals while this client sends its own: with and
    without feedback callbacks, one rejected, one canceled, all at once. Every handle holds
    rclpy's status after every execute, and its sequence ends terminal; other goals' entries never
    reach Python."""
    action = '/' + unique_name('fib')
    server = start_server(action, guarded=guarded, period=0.02)
    others = None
    try:
        # The plain client starts now, so that its discovery of the server (up to Fast DDS's 3 s
        # announcement period) overlaps this client's set-up; it sends its goals on 'go' below.
        others = helper_process('harness.client', [action, 'rclpy', 60, 5, 1000], ready='')
        # Every client's response reader gets the responses to all clients: rclpy's keep-last
        # 10 would drop some in this burst, as for plain rclpy (README, "Differences from rclpy").
        deep = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        client = ShadowedClient(ros.node, Fibonacci, action, feedback_filter=mode,
                                goal_service_qos_profile=deep, result_service_qos_profile=deep,
                                cancel_service_qos_profile=deep)
        assert client.wait_for_server(timeout_sec=20)
        assert round_trip(ros, client), 'the server never answered a goal'
        others.expect('READY', 60)
        others.send('go')
        futures = [client.send_goal_async(Fibonacci.Goal(order=k % 6),
                                          (lambda _: None) if k % 2 else None)
                   for k in range(12)]
        futures.append(client.send_goal_async(Fibonacci.Goal(order=-1)))  # rejected
        futures.append(client.send_goal_async(Fibonacci.Goal(order=1000)))  # canceled below
        assert ros.spin_until(lambda: all(f.done() for f in futures), 30)
        assert not futures[12].result().accepted
        # No stale status: while others' goals churn, every live handle of this client comes to
        # hold the status that a plain status subscription's latest sample lists for it (the
        # reader filter dropped no sample that would have changed it).
        latest = plain_status_subscription(ros, action)
        live = [f.result() for f in futures if f.result().accepted]

        def current() -> bool:
            listed = {bytes(s.goal_info.goal_id.uuid): s.status
                      for s in (latest[0].status_list if latest else [])}
            return all(h.status == listed.get(bytes(h.goal_id.uuid), h.status) for h in live) \
                and listed.get(bytes(futures[13].result().goal_id.uuid)) \
                == GoalStatus.STATUS_EXECUTING
        def stale() -> list[str]:
            listed = {bytes(s.goal_info.goal_id.uuid): s.status
                      for s in (latest[0].status_list if latest else [])}
            return [f'{bytes(h.goal_id.uuid).hex()[:8]}: handle {h.status}, listed '
                    f'{listed.get(bytes(h.goal_id.uuid))}' for h in live] + [
                'the goal to cancel is listed as '
                f'{listed.get(bytes(futures[13].result().goal_id.uuid))}',
                f'{len(listed)} goals in the latest sample', f'mismatches {client.mismatches[:5]}']
        # A handle made after the last sample that lists its goal waits for the next one, with
        # plain rclpy too; on a loaded machine the others' goals may all have ended by then, so
        # a goal of order 0 makes a new sample when none came for a while.
        nudges = []
        for _ in range(4):
            if ros.spin_until(current, 5):
                break
            nudges.append(client.send_goal_async(Fibonacci.Goal(order=0)))
        assert ros.spin_until(current, 5), (client.goal_status_state, stale())
        assert ros.spin_until(lambda: all(f.done() for f in nudges), 20)
        cancel = futures[13].result().cancel_goal_async()
        assert ros.spin_until(cancel.done, 20)
        accepted = [f.result() for f in futures + nudges if f.result().accepted]
        # Every goal accepted (the others', and both probes) and finished at the server.
        expected = len(accepted) + 60 + 2
        assert ros.spin_until(lambda: server_done(server, expected), 60), server.tail()
        # A handle made after the last status sample that lists its goal waits for the next
        # sample, with plain rclpy too (a goal response taken after the goal's last transition):
        # one more goal makes more samples, which list every goal the server holds.
        closing = client.send_goal_async(Fibonacci.Goal(order=1))
        assert ros.spin_until(closing.done, 20)
        assert ros.spin_until(lambda: server_done(server, expected + 1), 30), server.tail()
        assert ros.spin_until(lambda: all(h.status in _TERMINAL for h in accepted), 30), \
            {bytes(h.goal_id.uuid).hex(): h.status for h in accepted}
        ros.spin_for(0.5)
        assert client.mismatches == []
        assert set(client.handles) >= {bytes(h.goal_id.uuid) for h in accepted}
        for handle in accepted:
            sequence = client.sequences[bytes(handle.goal_id.uuid)]
            assert sequence[-1] == client.final[bytes(handle.goal_id.uuid)]
        assert futures[13].result().status == GoalStatus.STATUS_CANCELED
        state = client.goal_status_state
        assert state.active and state.reason == ''
        # The others' 60 goals were listed in the samples; what reached Python was ours alone.
        assert client.whole_entries > state.delivered + 60
        assert state.entries == client.whole_entries
        assert server.poll() is None, server.tail()
    finally:
        if others is not None:
            others.stop()
        server.stop()


def own_goals_ended(ros, client, table) -> None:
    """Wait until none of the client's goals can still change, making status samples as needed.

    An order-0 goal's status samples can all arrive before its goal response is executed: its
    handle, made after them, then waits for the next sample that lists the goal, as with plain
    rclpy, and the table keeps the goal until then (seen once in a clean-clone ``CI=true`` run:
    the count stayed 1 for 20 s). Another goal makes the server publish samples that list every
    goal it holds, so each try settles the goals before it.
    """
    for _ in range(5):
        if ros.spin_until(lambda: table.counts()[3] == 0, 3):
            return
        extra = client.send_goal_async(Fibonacci.Goal(order=0))
        assert ros.spin_until(extra.done, 20), 'the server never answered a goal'
    assert table.counts()[3] == 0, (table.counts(), client.goal_status_state)


@pytest.mark.parametrize('guarded', [False, True], ids=['unguarded', 'guarded'])
def test_an_observer_without_live_goals_is_not_woken_by_others_status(ros, guarded):
    """Once its own goals have ended, the client's status reader drops every sample, since none can
    change its goal handles, guarded or not (no writer knows the status class): others' 60 goals
    make no status sample reach the trim, while a plain client next to it takes them."""
    action = '/' + unique_name('fib')
    server = start_server(action, guarded=guarded, period=0.02)
    others = None
    try:
        # Started now, so that its discovery of the server overlaps this client's set-up; its
        # round trip before READY is one more goal whose status samples the trim drops.
        others = helper_process('harness.client', [action, 'rclpy', 60, 2, 1000], ready='')
        client = ActionClient(ros.node, Fibonacci, action)
        assert client.goal_status_state.filtered and client.goal_status_state.prompt_acks
        assert client.wait_for_server(timeout_sec=20)
        assert round_trip(ros, client), 'the server never answered a goal'
        table = client._status._table
        own_goals_ended(ros, client, table)
        before = client.goal_status_state
        others.expect('READY', 60)
        others.send('go')
        assert ros.spin_until(lambda: server_done(server, 60 + 2), 60), server.tail()
        ros.spin_for(0.5)
        report = others.request_json('report', 'RESULT')
        assert report['status'] > 0  # the plain client took status samples
        after = client.goal_status_state
        assert (after.samples, after.delivered) == (before.samples, before.delivered)
        assert server.poll() is None, server.tail()
    finally:
        if others is not None:
            others.stop()
        server.stop()
