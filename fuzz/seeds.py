# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Write the seed corpus of fuzz/ (fuzz/corpus/<target>/seed_*) from real expressions and samples.

The expressions are the ones the library writes (cft_action.topics.filters, .topics.rate,
.parameters._parameter_event_filter, the status table's), and the samples are messages serialized
by rclpy, as a remote participant would send them. Each harness's input format is in its own
file's header comment. Run with the venv's Python from the repository's root:
``.venv/bin/python fuzz/seeds.py``. Regression inputs (regress_*) are kept by hand, never written.
"""

from __future__ import annotations

import struct
from pathlib import Path

from action_msgs.msg import GoalInfo, GoalStatus, GoalStatusArray
from rcl_interfaces.msg import Parameter, ParameterEvent, ParameterValue
from rclpy.serialization import serialize_message
from test_msgs.action import Fibonacci

from cft_action.parameters._parameter_event_filter import node_filter, NO_NODES
from cft_action.topics.filters import goal_filter_expression, uuid_prefix_term
from cft_action.topics.rate import RateFilter

CORPUS = Path(__file__).resolve().parent / 'corpus'
PREFIX = bytes.fromhex('010f4a6e2b3c000001000000')  # a participant's GUID prefix
READER = PREFIX + bytes.fromhex('00001204')  # a user reader's entity id
PARTICIPANT = PREFIX + bytes.fromhex('000001c1')
UUIDS = [bytes(range(i, i + 16)) for i in (1, 40, 200)]
STATUS_TYPE = 'action_msgs::msg::dds_::GoalStatusArray_'
FEEDBACK_TYPE = 'test_msgs::action::dds_::Fibonacci_FeedbackMessage_'
EVENT_TYPE = 'rcl_interfaces::msg::dds_::ParameterEvent_'


def feedback(uuid: bytes, n: int) -> bytes:
    message = Fibonacci.Impl.FeedbackMessage()
    message.goal_id.uuid = list(uuid)
    message.feedback.sequence = list(range(n))
    return serialize_message(message)


def status_array(entries: list[tuple[bytes, int]]) -> bytes:
    message = GoalStatusArray()
    for uuid, status in entries:
        info = GoalInfo()
        info.goal_id.uuid = list(uuid)
        info.stamp.sec, info.stamp.nanosec = 1765000000, 5
        message.status_list.append(GoalStatus(goal_info=info, status=status))
    return serialize_message(message)


def event(node: str) -> bytes:
    message = ParameterEvent(node=node)
    message.stamp.sec = 1765000000
    message.changed_parameters = [Parameter(name='rate', value=ParameterValue(type=3,
                                                                              double_value=2.5))]
    return serialize_message(message)


def sample(data: bytes) -> bytes:
    """A sample as the harnesses read one: a 2-byte little-endian length, then its bytes."""
    return struct.pack('<H', len(data)) + data


def text(*parts: str) -> bytes:
    return b''.join(p.encode() + b'\0' for p in parts)


def rpd(class_name: str, expression: str, *, type_name: str, topic: str,
        params: tuple[str, ...] = (), related: str | None = None, shift: int = 0) -> bytes:
    """A reader's discovery data, as fuzz_rpd_read (fuzz_common.h) reads it."""
    return (bytes([16 + shift // 4]) + READER + bytes([len(params)])
            + text(type_name, topic, class_name, topic if related is None else related)
            + sample(expression.encode()) + text(*params))


def rate_ops(*ops: tuple[int, int, int]) -> bytes:
    return b''.join(struct.pack('<BBQ', op, writer, step) for op, writer, step in ops)


def rate_expression(max_rate: float | None, poll: int | None, *more: int) -> str:
    rate = RateFilter(max_rate, poll)
    for n in more:
        rate.poll(n)
    return rate.expression()


def seeds() -> dict[str, dict[str, bytes]]:
    one, many = goal_filter_expression([UUIDS[0][:4]]), goal_filter_expression(
        [u[:4] for u in UUIDS] + [UUIDS[0]])
    params = tuple(str(b) for b in UUIDS[1])
    with_params = ' AND '.join(f'goal_id.uuid[{i}] = %{i}' for i in range(16))
    names = ['/robot/planner', '/robot/driver']
    node_options = node_filter(names, parameters=False)
    status = status_array([(UUIDS[0], 2), (UUIDS[1], 4), (UUIDS[2], 1)])
    status_topic, feedback_topic = 'rt/fibonacci/_action/status', 'rt/fibonacci/_action/feedback'
    slow, polled = rate_expression(2.0, None), rate_expression(None, 0, 3, 2)
    return {
        'uuid': {
            'seed_one_goal': UUIDS[0] + one.encode(),
            'seed_goals': UUIDS[1] + many.encode(),
            'seed_full_uuid': UUIDS[2] + uuid_prefix_term(UUIDS[2]).encode(),
            'seed_params': UUIDS[1] + text(f'({with_params}) OR goal_id.uuid[0] = 7', *params),
        },
        'node': {
            'seed_names': text(node_options.filter_expression) + event('/robot/driver'),
            'seed_all': text('node = node') + event('/other'),
            'seed_none': text(NO_NODES) + event('/robot/planner'),
        },
        'rate': {
            'seed_period': text(slow, rate_expression(10.0, None)) + rate_ops(
                (0, 1, 0), (0, 1, 10**8), (0, 2, 6 * 10**8), (2, 1, 0), (0, 1, 10**9)),
            'seed_poll': text(polled, rate_expression(None, 0, 3, 2, 4)) + rate_ops(
                (0, 1, 5), (1, 1, 5), (0, 3, 5), (130, 0, 5), (0, 1, 5), (0, 79, 5)),
        },
        'status_trim': {
            'seed_table': text('cft_status_table = 1') + bytes([2]) + UUIDS[0] + b'\x03'
            + UUIDS[1] + b'\x00' + b'\x81' + status,
            'seed_pending': text('cft_status_table = 7') + bytes([1]) + UUIDS[2] + b'\x00'
            + b'\x40' + status,
        },
        'guard_status': {
            'seed_requests': bytes([2]) + UUIDS[0] + READER + UUIDS[2] + PARTICIPANT
            + text('cft_status_table = 3') + READER + b'\x00' + sample(status)
            + sample(status_array([(UUIDS[0], 4), (UUIDS[1], 4)])),
            'seed_owed': bytes([1]) + UUIDS[1] + READER + text('cft_status_table = 1') + READER
            + b'\x03' + sample(status) + sample(status),
        },
        'filter_class': {
            'seed_uuid': text('CFT_ACTION_UUID', one, many) + b'\x00\x01' + sample(
                feedback(UUIDS[0], 3)) + b'\x81\x01\x00\x01' + sample(feedback(UUIDS[1], 1)),
            'seed_node': text('CFT_ACTION_NODE', node_options.filter_expression, 'node = node')
            + b'\x00\x01' + sample(event('/robot/planner')),
            'seed_rate': text('CFT_ACTION_RATE', slow, polled) + b'\x00\x01' + sample(b'\0\1\0\0')
            + b'\x20\x01' + sample(b'\0\1\0\0') + b'\x02\x01\x81\x01\x00\x02' + sample(b''),
            'seed_status': text('CFT_ACTION_STATUS', 'cft_status_table = 1', '') + b'\x00\x01'
            + sample(status),
        },
        'guard_filter': {
            'seed_ddssql_uuid': rpd('DDSSQL', with_params, type_name=FEEDBACK_TYPE,
                                    topic=feedback_topic, params=params) + b'\x00'
            + b'\x00' + sample(feedback(UUIDS[1], 2)),
            'seed_uuid_class': rpd('CFT_ACTION_UUID', many, type_name=FEEDBACK_TYPE,
                                   topic=feedback_topic, shift=8) + b'\x01'
            + b'\x00' + sample(feedback(UUIDS[0], 2)) + b'\x01' + sample(b''),
            'seed_status_class': rpd('CFT_ACTION_STATUS', 'cft_status_table = 2',
                                     type_name=STATUS_TYPE, topic=status_topic) + b'\x01'
            + b'\x00' + sample(status),
            'seed_node_class': rpd('CFT_ACTION_NODE', node_options.filter_expression,
                                   type_name=EVENT_TYPE, topic='rt/parameter_events') + b'\x01'
            + b'\x00' + sample(event('/robot/planner')),
        },
        'guard_programs': {
            'seed_rate': b'\x00' + sample(f'CFT_ACTION_RATE {slow}'.encode()) + b'\x01'
            + sample(b'\0\1\0\0') + b'\x01' + sample(b'\0\1\0\0') + b'\x00'
            + sample(f'CFT_ACTION_RATE {polled}'.encode()) + b'\x01' + sample(b''),
            'seed_node': b'\x00' + sample(f'CFT_ACTION_NODE {node_options.filter_expression}'
                                          .encode()) + b'\x01' + sample(event('/robot/driver'))
            + b'\x01' + sample(event('/other')) + b'\x00' + sample(b'CFT_ACTION_NODE node = node'),
        },
        'writer_marks': {
            'seed_marked_writer': sample(b'typehash=RIHS01_' + b'ab' * 32 + b';cft_action=filters;')
            + b'\x00' + PARTICIPANT + rpd('', '', type_name=FEEDBACK_TYPE, topic=feedback_topic)
            + b'\x40',
            'seed_filtered_reader': sample(b'typehash=RIHS01_' + b'cd' * 32 + b';') + b'\x08'
            + PARTICIPANT + rpd('CFT_ACTION_UUID', one, type_name=FEEDBACK_TYPE,
                                topic=feedback_topic) + b'\x40',
        },
    }


def main() -> None:
    for target, files in seeds().items():
        folder = CORPUS / target
        folder.mkdir(parents=True, exist_ok=True)
        for stale in folder.glob('seed_*'):
            stale.unlink()
        for name, data in files.items():
            (folder / name).write_bytes(data)


if __name__ == '__main__':
    main()
