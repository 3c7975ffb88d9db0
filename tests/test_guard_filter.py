# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The server guard's uuid filter verdicts (cft_action/native/guard/_guard_filter.c) give Fast DDS's
verdicts.

- The layout the guard reads (ReaderProxyData, ContentFilterProperty, SerializedPayload_t) is the
  one of the installed Fast DDS headers.
- Its grammar compiles exactly the uuid-only expressions, and their verdicts equal those of
  ``cft_action.topics.sql`` (which agrees with Fast DDS: tests/test_topic_cli.py), over UUIDs that
  share 1, 2, 3 and 4 bytes with a client's tag.
- On the real stack, a guarded publisher with ``CFT_GUARD_VERIFY=1`` asks Fast DDS for every verdict
  it gives, and they never disagree; each reader gets exactly the samples its filter matches.
- A filter changed while the server publishes is answered with the new filter from then on.
- A guard whose layout does not match the loaded Fast DDS (built here from a deliberately wrong
  layout header) says so once, leaves every verdict to Fast DDS, and the server keeps publishing.
"""

from __future__ import annotations

import ctypes
import itertools
import os
import random
import shutil
import subprocess
from pathlib import Path
from typing import Iterator

import pytest
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from test_msgs.action import Fibonacci

from cft_action import create_filtered_subscription, guard, set_content_filter
from cft_action.topics import sql
from cft_action.topics.filters import MATCH_ALL, NEVER_MATCH, any_of, uuid_prefix_term
from cft_action.topics.message_types import message_schema
from harness.proc import stop_all
from harness.ros import unique_name
from tests.support import fastdds_header_probe, helper_process

FEEDBACK = Fibonacci.Impl.FeedbackMessage
SCHEMA = message_schema(FEEDBACK)
TAG = bytes([220, 130, 200, 79])
EXACT = bytes(range(100, 116))


def uuids(seed: int = 7) -> list[bytes]:
    """UUIDs that start with the tag, share 1, 2 or 3 of its bytes, or are random."""
    rng = random.Random(seed)
    out = [TAG + rng.randbytes(12) for _ in range(3)]
    for shared in (1, 2, 3):
        for positions in itertools.combinations(range(4), shared):
            head = bytes(TAG[i] if i in positions else (TAG[i] + 1 + rng.randrange(254)) % 256
                         for i in range(4))
            out.append(head + rng.randbytes(12))
    out += [rng.randbytes(16) for _ in range(5)]
    out += [EXACT, bytes([16]) + rng.randbytes(15), bytes([8]) + rng.randbytes(15),
            bytes([200, 130]) + rng.randbytes(14), bytes(16)]
    return out


def feedback(k: int, uuid: bytes) -> FEEDBACK:
    message = FEEDBACK()
    message.goal_id.uuid = list(uuid)
    message.feedback.sequence = [k]
    return message


def upstream_terms(uuid: bytes, first: int = 0) -> str:
    """The upstream (Rolling) design's goal term: 16 parameters."""
    return ' AND '.join(f'goal_id.uuid[{i}] = %{first + i}' for i in range(16))


#: (expression, parameters, whether the guard answers it itself).
CORPUS = [
    (uuid_prefix_term(TAG), [], True),                                   # client mode
    (any_of([uuid_prefix_term(TAG), uuid_prefix_term(EXACT)]), [], True),  # + a caller's UUID
    (any_of(uuid_prefix_term(TAG[:2] + bytes([b, 1])) for b in (0, 200, 201)), [], True),
    (NEVER_MATCH, [], True),
    (MATCH_ALL, [], True),
    (upstream_terms(EXACT), [str(b) for b in EXACT], True),
    (f'({upstream_terms(EXACT)}) OR ({upstream_terms(TAG * 4, 16)})',
     [str(b) for b in EXACT + TAG * 4], True),
    ('goal_id.uuid[0]=220 AND goal_id.uuid[1]=130', [], True),
    ('(goal_id.uuid[0] = 220) AND (goal_id.uuid[3] = 79 AND goal_id.uuid[2] = 200)', [], True),
    ('goal_id.uuid[0] = 200 OR goal_id.uuid[1] = 130', [], True),
    # Left to Fast DDS: mixed connectives, other operators, other literals, other fields.
    ('goal_id.uuid[0] = 200 OR goal_id.uuid[1] = 130 AND goal_id.uuid[2] = 200', [], False),
    ('goal_id.uuid[0] > 100', [], False),
    ('goal_id.uuid[0] <> 220', [], False),
    ('goal_id.uuid[0] = 0x10', [], False),
    ('goal_id.uuid[0] = 010', [], False),
    ('goal_id.uuid[0] = %0', ['0x10'], False),
    ('goal_id.uuid[0] = goal_id.uuid[1]', [], False),
    ('NOT goal_id.uuid[0] = 220', [], False),
    ('feedback.sequence[0] > 10', [], False),
    ('goal_id.uuid[0] = 220 AND feedback.sequence[0] >= 0', [], False),
]
CORPUS_IDS = [f'{"uuid" if own else "fastdds"}-{i}' for i, (_, _, own) in enumerate(CORPUS)]


def expected_keys(expression: str, params: list[str], published: list[tuple[int, bytes]]
                  ) -> list[int]:
    compiled = sql.compile_filter(expression, params, SCHEMA)
    return [k for k, uuid in published if compiled.matches(feedback(k, uuid))]


# --- the layout --------------------------------------------------------------------------------

LAYOUT_PROBE = r'''
#include <fastdds/rtps/builtin/data/ReaderProxyData.h>
#include <fastdds/rtps/common/CacheChange.h>
#include <fastdds/rtps/common/SerializedPayload.h>
#include <fastdds/dds/topic/IContentFilter.hpp>
#include <cstddef>
#include <cstdio>
#include <cstring>
using namespace eprosima::fastrtps::rtps;
using eprosima::fastdds::rtps::ContentFilterProperty;
using eprosima::fastrtps::string_255;
static long diff(const void* a, const void* b) { return (const char*)a - (const char*)b; }
int main() {
  alignas(ReaderProxyData) static char storage[sizeof(ReaderProxyData)];
  auto* rpd = reinterpret_cast<ReaderProxyData*>(storage);  // inline accessors only
  ContentFilterProperty::AllocationConfiguration config;
  ContentFilterProperty cfp(config);
  cfp.expression_parameters.push_back("17");
  const char* rlv = reinterpret_cast<const char*>(&cfp.expression_parameters);
  long vector_at = -1;
  for (long at = 0; at + 8 <= (long)sizeof(cfp.expression_parameters); at += 8) {
    const void* word;
    memcpy(&word, rlv + at, sizeof word);
    if (word == &cfp.expression_parameters[0]) vector_at = at;
  }
  string_255 s("abc");
  long length_at = -1;
  for (long at = 0; at + 8 <= (long)sizeof s; at += 8) {
    size_t word;
    memcpy(&word, reinterpret_cast<const char*>(&s) + at, sizeof word);
    if (word == 3 && at >= 4) length_at = at;
  }
  CacheChange_t change;  // public members: the offsets measured on an object
  eprosima::fastdds::dds::IContentFilter::FilterSampleInfo info;
  printf("%ld %ld %zu %zu %zu %zu %ld %zu %ld %zu %zu %ld %ld %ld %ld %zu %ld %zu %ld %ld %ld"
         " %ld\n",
         diff(&rpd->typeName(), rpd), diff(&rpd->content_filter(), rpd),
         offsetof(ContentFilterProperty, related_topic_name),
         offsetof(ContentFilterProperty, filter_class_name),
         offsetof(ContentFilterProperty, filter_expression),
         offsetof(ContentFilterProperty, expression_parameters), vector_at, sizeof(string_255),
         length_at, offsetof(SerializedPayload_t, length), offsetof(SerializedPayload_t, data),
         diff(&rpd->guid(), rpd), diff(&rpd->key(), rpd), diff(&rpd->topicName(), rpd),
         diff(&change.kind, &change), sizeof change.kind, diff(&change.serializedPayload, &change),
         offsetof(SerializedPayload_t, max_size), diff(&change.writerGUID, &change),
         diff(&change.write_params.related_sample_identity().writer_guid(), &change),
         diff(&change.write_params.related_sample_identity().sequence_number(), &change),
         diff(&info.sample_identity.writer_guid(), &info));
  return 0;
}
'''


#: The names of cft_guard_filter_layout()'s values, in its order (the _fastdds_layout.h names).
LAYOUT_NAMES = ('RPD_TYPE_NAME', 'RPD_CONTENT_FILTER', 'CFP_RELATED_TOPIC', 'CFP_CLASS_NAME',
                'CFP_EXPRESSION', 'CFP_PARAMETERS', 'RLV_VECTOR', 'STRING255_SIZE',
                'STRING255_LENGTH', 'PAYLOAD_LENGTH', 'PAYLOAD_DATA', 'RPD_GUID', 'RPD_KEY',
                'RPD_TOPIC_NAME', 'CC_KIND', 'CC_KIND_SIZE', 'CC_PAYLOAD', 'PAYLOAD_MAX_SIZE',
                'CC_WRITER_GUID', 'CC_RELATED_WRITER_GUID', 'CC_RELATED_SEQUENCE',
                'FSI_WRITER_GUID')


def guard_library() -> ctypes.CDLL:
    """The guard's C API, loaded locally: it interposes nothing in this process."""
    return ctypes.CDLL(guard.library_path(), mode=os.RTLD_LOCAL)


def test_the_layout_is_that_of_the_installed_fast_dds_headers(tmp_path: Path) -> None:
    headers = fastdds_header_probe(LAYOUT_PROBE, tmp_path)
    library = guard_library()
    library.cft_guard_filter_layout.restype = ctypes.c_long
    ours = [library.cft_guard_filter_layout(i) for i in range(len(headers))]
    assert ours == headers
    assert len(headers) == len(LAYOUT_NAMES)
    assert library.cft_guard_filter_layout(len(headers)) == -1


def guard_sources() -> list[Path]:
    """The C files that setup.py builds into the guard: those of native/guard/ and of native/."""
    native = Path(guard.__file__).parent / 'native'
    return sorted((native / 'guard').glob('*.c')) + sorted(native.glob('*.c'))


def guard_built_with(layout: dict[str, int], tmp_path: Path) -> Path:
    """The guard's C files built into ``tmp_path`` with ``layout`` as their _fastdds_layout.h."""
    compiler = shutil.which('cc') or shutil.which('gcc')
    parts = guard_sources()
    if compiler is None or not parts:
        pytest.skip("needs a C compiler and the guard's C files")
    header = ['#define CFT_LAYOUT_KNOWN 1',
              '#define CFT_LAYOUT_SOURCE "a layout made up by tests/test_guard_filter.py"',
              '#define CFT_LAYOUT_INCLUDES ""']
    header += [f'#define {name} {value}' for name, value in layout.items()]
    (tmp_path / '_fastdds_layout.h').write_text('\n'.join(header) + '\n')
    library = tmp_path / 'libcftguard_wrong_layout.so'
    subprocess.run([compiler, '-shared', '-fPIC', '-O2', '-fvisibility=hidden', '-fexceptions',
                    f'-I{tmp_path}', *sorted({f'-I{part.parent}' for part in parts}),
                    *map(str, parts), '-o', str(library), '-ldl', '-lpthread'],
                   check=True, capture_output=True, timeout=120)
    return library


# --- the grammar ------------------------------------------------------------------------------

def guard_try(library: ctypes.CDLL, expression: str, params: list[str], uuid: bytes) -> int:
    array = (ctypes.c_char_p * max(1, len(params)))(*[p.encode() for p in params])
    return library.cft_uuid_filter_try(expression.encode(), array, len(params), uuid)


@pytest.mark.parametrize('expression, params, own', CORPUS, ids=CORPUS_IDS)
def test_compiled_verdicts_equal_the_sql_evaluator(expression: str, params: list[str],
                                                   own: bool) -> None:
    library = guard_library()
    library.cft_uuid_filter_try.restype = ctypes.c_int
    compiled = sql.compile_filter(expression, params, SCHEMA)
    rng = random.Random(expression)
    for uuid in uuids() + [rng.randbytes(16) for _ in range(200)]:
        verdict = guard_try(library, expression, params, uuid)
        if not own:
            assert verdict == -1, f'the guard compiled {expression!r}'
            continue
        assert verdict == compiled.matches(feedback(0, uuid)), (expression, uuid.hex())


@pytest.mark.parametrize('expression', [
    '', 'goal_id.uuid[16] = 0', 'goal_id.uuid[0] = 256', 'goal_id.uuid[0] = -1',
    'goal_id.uuid[0] = 1.0', 'goal_id.uuid[0] = 1e2', 'goal_id.uuid[00] = 1',
    'goal_id.uuid[0] == 1', 'goal_id.uuid[0] = 1 and goal_id.uuid[1] = 2',
    'goal_id.uuid[0] = 1 AND', '(goal_id.uuid[0] = 1', 'goal_id.uuid[0] = 1)',
    'goal_id.uuid[0] = 1 OR (goal_id.uuid[1] = 2 OR goal_id.uuid[2] = 3)',
    'goal_id.uuid = 1', 'goal_id.uuid[0] = 1 ANDgoal_id.uuid[1] = 2', 'goal_id.uuid[0] = %1',
])
def test_anything_outside_the_grammar_goes_to_fast_dds(expression: str) -> None:
    library = guard_library()
    assert guard_try(library, expression, ['5'], bytes(16)) == -1


# --- the real stack ---------------------------------------------------------------------------

KEEP_ALL = QoSProfile(depth=1, history=HistoryPolicy.KEEP_ALL,
                      reliability=ReliabilityPolicy.RELIABLE)


@pytest.fixture
def publisher() -> Iterator:
    """Start a guarded feedback publisher with the given guard settings; stops it after the test."""
    started = []

    def start(action: str, **settings: str):
        child = helper_process('tests.helpers.feedback_publisher', [action],
                               env=guard.environment({**os.environ, **settings}))
        started.append(child)
        return child

    yield start
    stop_all(started)


class Reader:
    """A filtered subscription on an action's feedback topic that records the K of each sample."""

    def __init__(self, ros, action: str, expression: str, params: list[str]) -> None:
        self.keys: list[int] = []
        self.subscription = create_filtered_subscription(
            ros.node, FEEDBACK, f'{action}/_action/feedback',
            lambda m: self.keys.append(m.feedback.sequence[0]), KEEP_ALL, expression, params)


def publish(child, published: list[tuple[int, bytes]]) -> None:
    for k, uuid in published:
        child.send(f'pub {k} {uuid.hex()}')


def prove_readers(ros, child, readers: list[Reader], proofs: list[bytes],
                  failure: str = 'the publisher never reached every reader') -> None:
    """Forget what the readers got, publish a sample of each UUID in ``proofs``, round after round,
    until each reader got one (every reader's filter must pass one of them); then forget those too.

    The publisher's ``wait N`` counts the readers its writer matched, and rmw_fastrtps replaces a
    reader when its first filter is set (docs/INTERNALS.md section 4): the count can include the
    replaced readers, and what is published before the writer matched the new ones never reaches
    them (seen once in a clean-clone ``CI=true`` run:
    test_a_changed_filter_is_answered_with_the_new_filter got nothing of its first batch in 20 s).
    A changed filter reaches the writer the same way, by discovery. Keys from 500 are the proof's.
    """
    for reader in readers:
        reader.keys.clear()
    keys = itertools.count(500)
    for _ in range(100):
        for uuid in proofs:
            child.send(f'pub {next(keys)} {uuid.hex()}')
        if ros.spin_until(lambda: all(r.keys for r in readers), timeout=0.2):
            break
    assert all(r.keys for r in readers), f'{failure}: {[r.keys for r in readers]}'
    ros.spin_for(0.3)  # proof samples still on the way
    for reader in readers:
        reader.keys.clear()


def test_verdicts_on_the_real_stack_equal_fast_dds(ros, publisher) -> None:
    action = '/' + unique_name('cft_verdicts')
    child = publisher(action, CFT_GUARD_VERIFY='1')
    readers = [Reader(ros, action, expression, params) for expression, params, _ in CORPUS]
    assert child.request(f'wait {len(readers)}', 'MATCHED', timeout=40) == 'MATCHED'
    published = list(enumerate(uuids() * 5))
    expected = [expected_keys(e, p, published) for e, p, _ in CORPUS]
    assert any(expected) and not all(expected)
    # Every reader whose filter passes one of the UUIDs: a reader that gets nothing proves nothing.
    prove_readers(ros, child, [r for r, keys in zip(readers, expected) if keys], uuids())
    publish(child, published)
    ros.spin_until(lambda: all(len(r.keys) >= len(x) for r, x in zip(readers, expected)),
                   timeout=30)
    ros.spin_for(1.0)
    for (expression, _, _), reader, keys in zip(CORPUS, readers, expected):
        assert sorted(reader.keys) == keys, expression
    counts = child.request_json('stats', 'STATS')
    own = sum(1 for _, _, mine in CORPUS if mine)
    assert counts['mismatches'] == 0, counts
    assert counts['compiled'] >= own, counts
    assert counts['verified'] == counts['uuid_verdicts'] >= own * len(published), counts
    assert counts['fastdds_verdicts'] >= (len(CORPUS) - own) * len(published), counts
    # The headers' layout was checked on the loaded Fast DDS's own reader data (as is on the wheels,
    # moved on a security build such as apt's).
    assert 'checked on the loaded Fast DDS' in counts['layout'], counts


def test_a_changed_filter_is_answered_with_the_new_filter(ros, publisher) -> None:
    action = '/' + unique_name('cft_change')
    child = publisher(action)  # no verification: the guard's own verdicts decide
    old, new = uuid_prefix_term(TAG), uuid_prefix_term(EXACT[:4])
    reader = Reader(ros, action, old, [])
    assert child.request('wait 1', 'MATCHED', timeout=40) == 'MATCHED'
    prove_readers(ros, child, [reader], [TAG + bytes(12)])
    batch = [TAG + bytes(12), EXACT, bytes(16)]
    publish(child, [(1, u) for u in batch])
    assert ros.spin_until(lambda: reader.keys == [1], timeout=20), reader.keys

    set_content_filter(reader.subscription, new)
    # Until the change reaches the writer it applies the old filter: probe until the new one
    # lets a sample through, then every sample must follow the new filter only.
    prove_readers(ros, child, [reader], [EXACT], 'the new filter never reached the writer')
    publish(child, [(1000 + i, u) for i, u in enumerate(batch * 10)])
    ros.spin_until(lambda: len(reader.keys) >= 10, timeout=20)
    ros.spin_for(1.0)
    assert reader.keys == [1000 + 3 * i + 1 for i in range(10)]
    counts = child.request_json('stats', 'STATS')
    assert counts['compiled'] >= 2 and counts['uuid_verdicts'] > 0, counts
    assert counts['fastdds_verdicts'] == 0, counts


def test_a_layout_the_guard_cannot_verify_leaves_every_verdict_to_fast_dds(ros, tmp_path) -> None:
    """A guard built from a layout that is not the loaded Fast DDS's: every field from m_key on
    8 bytes later than the headers say, as a build that inserted a member there would have them."""
    library = guard_library()
    library.cft_guard_filter_layout.restype = ctypes.c_long
    library.cft_guard_writer_qos_layout.restype = ctypes.c_long
    layout = {name: library.cft_guard_filter_layout(i) for i, name in enumerate(LAYOUT_NAMES)}
    layout['DWQ_READER_FILTERS'] = library.cft_guard_writer_qos_layout(0)
    for name in ('RPD_KEY', 'RPD_TYPE_NAME', 'RPD_TOPIC_NAME', 'RPD_CONTENT_FILTER'):
        layout[name] += 8
    wrong = guard_built_with(layout, tmp_path)
    preload = [str(wrong)] + os.environ.get('LD_PRELOAD', '').split()
    action = '/' + unique_name('cft_wrong_layout')
    child = helper_process('tests.helpers.feedback_publisher', [action],
                           env={**os.environ, 'LD_PRELOAD': ' '.join(preload)})
    try:
        expression = uuid_prefix_term(TAG)
        readers = [Reader(ros, action, expression, []) for _ in range(2)]
        assert child.request('wait 2', 'MATCHED', timeout=40) == 'MATCHED'
        prove_readers(ros, child, readers, [TAG + bytes(12)])
        for round_ in range(2):  # the server keeps publishing after it turned its verdicts off
            published = [(100 * round_ + k, uuid) for k, uuid in enumerate(uuids())]
            publish(child, published)
            expected = expected_keys(expression, [], published)
            assert ros.spin_until(lambda want=expected: all(r.keys[-len(want):] == want
                                                            for r in readers),
                                  timeout=30), [r.keys for r in readers]
        counts = child.request_json('stats', 'STATS')
        assert counts['compiled'] == 0 and counts['uuid_verdicts'] == 0, counts
        assert counts['fastdds_verdicts'] >= 2 * 2 * len(uuids()), counts
        assert counts['layout'].startswith('the loaded Fast DDS'), counts
        assert 'a layout made up by tests/test_guard_filter.py' in counts['layout'], counts
        assert child.popen.poll() is None
        said = [line for line in child.all('[cft_action guard') if 'filter verdicts off' in line]
        assert len(said) == 1, said
        assert counts['layout'] in said[0]
    finally:
        child.stop()
