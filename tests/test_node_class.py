"""The library's filter class for parameter events, CFT_ACTION_NODE
(cft_action/native/_node_program.c).

A ParameterEventHandler's node filter uses it, so that only guarded nodes' writers filter: a node
that nobody put under the guard does not know the class, sends every event, and the handler's
reader drops the other nodes' events itself.
"""

import ctypes
import random
import string

import pytest
from rcl_interfaces.msg import ParameterEvent
from rclpy.serialization import serialize_message

from cft_action import _native, ContentFilterError, guard
from cft_action.parameters.parameter_events import (ALL_NODES, NO_NODES, node_filter,
                                                    ParameterEventHandler)
from harness.ros import unique_name
from tests.support import helper_process, prove_parameter_events
from tests.test_parameter_events import BURST, burst

EVERY, NONE, NOT_COMPILED, UNREADABLE = 1, 0, -1, -2


class _Payload(ctypes.Structure):
    """SerializedPayload_t's head: tests/test_uuid_class.py checks these offsets (4, 8)."""

    _fields_ = [('encapsulation', ctypes.c_uint16), ('length', ctypes.c_uint32),
                ('data', ctypes.c_void_p)]


@pytest.fixture(scope='module')
def verdict():
    lib = ctypes.CDLL(_native.extension_path(_native.READER_LOCK_LIBRARY))
    lib.cft_node_filter_try.restype = ctypes.c_int
    lib.cft_node_filter_try.argtypes = [ctypes.c_char_p, ctypes.POINTER(_Payload)]

    def judge(expression: str, event: bytes) -> int:
        buffer = ctypes.create_string_buffer(event, len(event))
        payload = _Payload(0, len(event), ctypes.cast(buffer, ctypes.c_void_p))
        return lib.cft_node_filter_try(expression.encode(), ctypes.byref(payload))
    return judge


def event(node: str, sec: int = 7) -> bytes:
    message = ParameterEvent(node=node)
    message.stamp.sec = sec
    return serialize_message(message)


def big_endian(node: str) -> bytes:
    """The same event as plain CDR in big endian, as another vendor's writer may send it."""
    raw = node.encode() + b'\0'
    return (b'\0\0\0\0' + (7).to_bytes(4, 'big') + (0).to_bytes(4, 'big')
            + len(raw).to_bytes(4, 'big') + raw + b'\0' * (-len(raw) % 4) + b'\0' * 12)


def random_node(rng: random.Random) -> str:
    def word():
        rest = string.ascii_lowercase + string.digits + '_'
        return rng.choice(string.ascii_lowercase) + ''.join(
            rng.choice(rest) for _ in range(rng.randint(0, 8)))
    return '/' + '/'.join(word() for _ in range(rng.randint(1, 3)))


def class_expression(names):
    return node_filter(names, parameters=False).filter_expression


@pytest.mark.parametrize('count', [1, 2, 5, 100, 101, 300])
def test_verdicts_are_exact_for_names_near_the_watched_ones(verdict, count):
    """Exactly the watched nodes pass: not a prefix, an extension or a case variant of one."""
    rng = random.Random(count)
    watched = sorted({random_node(rng) for _ in range(count)})
    expression = class_expression(watched)
    near = [n + suffix for n in watched[:20] for suffix in ('x', '/a', '_')]
    near += [n[:-1] for n in watched[:20]] + [n.upper() for n in watched[:20]]
    near += [random_node(rng) for _ in range(200)] + ['', '/']
    for node in watched:
        assert verdict(expression, event(node)) == EVERY, node
        assert verdict(expression, big_endian(node)) == EVERY, node
    for node in set(near) - set(watched):
        assert verdict(expression, event(node)) == NONE, node
        assert verdict(expression, big_endian(node)) == NONE, node


def test_every_node_and_no_node(verdict):
    for node in ('/a', '/talker/x', ''):
        assert verdict(ALL_NODES, event(node)) == EVERY
        assert verdict(NO_NODES, event(node)) == NONE
    assert class_expression([]) == NO_NODES


@pytest.mark.parametrize('expression', [
    "node = %0", "node = 'a' AND node = 'b'", "stamp.sec > 1", "node = 'a' OR", "node LIKE '/a%'",
    "(node = '/a')", "node = '/a' OR stamp.sec = 1", "node = node OR node = '/a'", "node <> '/a'",
    "node = '/a", "", "nodes = '/a'"])
def test_expressions_outside_the_grammar_are_refused(verdict, expression):
    assert verdict(expression, event('/a')) == NOT_COMPILED


def test_an_event_whose_node_cannot_be_read_is_reported(verdict):
    good = event('/a')
    assert verdict("node = '/a'", good[:14]) == UNREADABLE  # the string is cut off
    assert verdict("node = '/a'", b'\0\x06' + good[2:]) == UNREADABLE  # not plain CDR


@pytest.mark.parametrize('guarded', [False, True], ids=['unguarded-nodes', 'guarded-nodes'])
def test_only_guarded_nodes_filter_on_their_side(ros, guarded):
    """A node that nobody put under the guard sends the handler every event, and the handler's
    reader drops the unwatched node's; a guarded node's writer does not send them."""
    prefix = '/' + unique_name('cft_nc')
    watched, other = f'{prefix}/watched', f'{prefix}/other'
    child = helper_process('harness.param_nodes', [watched, other],
                           env=guard.environment() if guarded else None)
    try:
        handler = ParameterEventHandler(ros.node)
        values = []
        handler.add_parameter_callback('value', watched,
                                       lambda p: values.append(p.value.integer_value))
        assert child.request('matched 1', 'MATCHED') == 'MATCHED'
        proof = prove_parameter_events(ros, handler, child, [watched])
        reader = handler._filter.reader
        judged = reader.reader_verdicts
        sent = burst(ros, handler, child, expected=BURST, proof=proof)
        assert sent.received == BURST, sent.evidence  # the watched node's only
        assert values == list(range(1, BURST + 1)), sent.evidence
        state = handler.parameter_event_filter_state
        if guarded:
            # No signature tells the reader that the writer filtered: it judges what arrives,
            # which is the watched node's events only.
            assert reader.reader_verdicts - judged == BURST, 'the writer sent events it rejects'
            assert state.filtered_in == 'writer'
        else:
            assert reader.reader_verdicts - judged >= 2 * BURST  # both nodes' events came
            assert state.filtered_in == 'reader'
        handler.destroy()
    finally:
        alive = child.poll() is None
        ended = child.stop()
    assert alive, f'param_nodes.py died\n{child.tail()}'
    assert ended == 0, f'param_nodes.py did not end cleanly\n{child.tail()}'


def test_a_dds_sql_expression_of_ones_own_needs_writer_filtering_any(ros):
    handler = ParameterEventHandler(ros.node)
    with pytest.raises(ContentFilterError, match="writer_filtering='any'"):
        handler.set_parameter_event_filter('node = %0 AND stamp.sec > %1', ['/a', 3])
    assert handler.get_parameter_event_filter() == (NO_NODES, [])
    handler.destroy()
