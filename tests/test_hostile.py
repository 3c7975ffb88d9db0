# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""A hostile participant against a guarded server (issue 46, docs/SAFETY.md "Who can send what").

Any participant on the domain can announce readers with whatever content filter it likes: the
filter's class, expression and parameters travel in its discovery data, and a guarded server reads
them. Here a plain Fast DDS participant (tests/helpers/hostile_reader.cpp, compiled against the
wheels' headers: no ROS, no cft_action) announces readers of the library's classes, of DDS-SQL and
of classes named like the library's, with malformed filters (:data:`HOSTILE`): expressions of
64 kB and past what a discovery parameter carries, 100 parameters, bytes that are not UTF-8 and
NULs, numbers out of range. It keeps one reader of each, beside plain readers of the same topics,
and churns 1,000 more, while a library client and a plain client run their goals on a server
under the guard (the guard's environment, which is what ``cft-action guard --`` execs with), and a
goal thief (tests/helpers/goal_thief.py) sends a goal request with each goal UUID it reads off the
status topic:

- the server serves both clients exactly (each gets every feedback of its goals and every status
  of them; the library client takes no foreign feedback, and its ``filtered_in`` stays
  ``'writer'``), the thief's requests are rejected and take no client's status;
- the guard says once what it refused (one line for expressions outside a class's grammar, one
  for class names like the library's, one for contested goal requests) and counts each, and says
  nothing else;
- each hostile reader receives what the plain reader of its topic receives, or nothing;
- the server's RSS after the 1,000 is within 10 % of its RSS after the first 100.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, NamedTuple, Optional

import pytest

from cft_action import guard
from harness import c_server, native_cache
from harness.proc import Proc, stop_all
from harness.ros import unique_name
from tests.support import action_server, helper_process

SOURCE = Path(__file__).resolve().parent / 'helpers' / 'hostile_reader.cpp'

FEEDBACK_TYPE = 'test_msgs::action::dds_::Fibonacci_FeedbackMessage_'
STATUS_TYPE = 'action_msgs::msg::dds_::GoalStatusArray_'
EVENTS_TYPE = 'rcl_interfaces::msg::dds_::ParameterEvent_'

GOALS = 3
ORDER = 5
CHURN_FIRST = 100
CHURN = 1000
CHURN_WINDOW = 20    # readers alive at once
CHURN_PAUSE_MS = 10  # between two readers: each lives about 200 ms, long enough to be announced
RSS_GROWTH = 1.10

TERM = b'goal_id.uuid[0] = 1 OR '


@dataclass(frozen=True)
class Hostile:
    """A reader's filter as the hostile participant announces it.

    ``topic``: 'feedback', 'status' or 'events' (/parameter_events); ``said``: what the guard
    counts it as (a key of ``guard.filter_counts()``), or None where Fast DDS decides (DDS-SQL),
    the reader is kept (a filter that compiles) or never announced whole (past 64 kB).
    """
    name: str
    topic: str
    filter_class: bytes
    expression: bytes
    parameters: tuple[bytes, ...] = ()
    said: Optional[str] = 'refused'
    nothing: bool = False  # it receives nothing (else every sample, as a plain reader)


#: The malformed filters (and two well-formed ones that match nothing). The churn takes those whose
#: name starts with 'h'; the plain readers' start with 'plain'.
HOSTILE = [
    Hostile('h_uuid_index', 'feedback', b'CFT_ACTION_UUID', b'goal_id.uuid[16] = 1'),
    Hostile('h_uuid_byte', 'feedback', b'CFT_ACTION_UUID', b'goal_id.uuid[0] = 256'),
    Hostile('h_uuid_digits', 'feedback', b'CFT_ACTION_UUID', b'goal_id.uuid[0] = ' + b'9' * 40),
    Hostile('h_uuid_negative', 'feedback', b'CFT_ACTION_UUID', b'goal_id.uuid[-1] = -1'),
    # 64 kB: the most a discovery parameter carries (its length is 16 bits), a trailing OR.
    Hostile('h_uuid_64k', 'feedback', b'CFT_ACTION_UUID', TERM * 2800),
    # 64 kB in the grammar, matching no goal: the guard keeps the reader, with 1,300 clauses.
    Hostile('h_uuid_64k_kept', 'feedback', b'CFT_ACTION_UUID',
            b' OR '.join([b'(goal_id.uuid[0] = 1 AND goal_id.uuid[0] = 2)'] * 1300), said=None,
            nothing=True),
    # Past 64 kB the announcing Fast DDS writes the parameter's length modulo 64 kB, and the
    # server reads the rest of the expression as further discovery parameters: its writers match
    # no such reader. Not churned: Fast DDS 2.14.5 keeps about 6.6 kB of each such announcement,
    # with or without the guard (docs/SAFETY.md, "Who can send what").
    Hostile('x_uuid_70k', 'feedback', b'CFT_ACTION_UUID', TERM * 3100 + b'goal_id.uuid[0] = 2',
            said=None, nothing=True),
    Hostile('h_uuid_utf8', 'feedback', b'CFT_ACTION_UUID', b'goal_id.uuid[0] = 1 \xff\xfe\xc0\x80'),
    # A NUL: Fast DDS hands the factory the text before it, which matches no goal.
    Hostile('h_uuid_nul', 'feedback', b'CFT_ACTION_UUID',
            b'goal_id.uuid[0] = 1 AND goal_id.uuid[0] = 2\x00 OR \xff', said=None,
            nothing=True),
    Hostile('h_uuid_params', 'feedback', b'CFT_ACTION_UUID', b'goal_id.uuid[0] = %99',
            tuple(str(i).encode() for i in range(100))),
    Hostile('h_uuid_params_utf8', 'feedback', b'CFT_ACTION_UUID', b'goal_id.uuid[0] = %0',
            (b'\xff\xfe',) * 100),
    Hostile('h_rate_period', 'feedback', b'CFT_ACTION_RATE', b'period=' + b'9' * 30),
    Hostile('h_rate_poll', 'feedback', b'CFT_ACTION_RATE', b'period=1 poll=5/6'),
    Hostile('h_node_quote', 'events', b'CFT_ACTION_NODE', b"node = 'a\xff' OR"),
    Hostile('h_node_mixed', 'events', b'CFT_ACTION_NODE', b"node = node AND node <> node OR x"),
    Hostile('h_status_table', 'status', b'CFT_ACTION_STATUS', b'cft_status_tabl\xff'),
    # The status class's form: kept, as the library's status readers, with no goal of its own.
    Hostile('h_status_kept', 'status', b'CFT_ACTION_STATUS', b'cft_status_table = \xff\xfe',
            said=None, nothing=True),
    # The status class on a feedback topic: the guard keeps only status readers, and Fast DDS knows
    # no such class.
    Hostile('h_status_on_feedback', 'feedback', b'CFT_ACTION_STATUS', b'cft_status_table = 1',
            said=None),
    Hostile('h_name_suffix', 'feedback', b'CFT_ACTION_UUID_V2', b'goal_id.uuid[0] = 1',
            said='unknown_classes'),
    Hostile('h_name_case', 'feedback', b'cft_action_uuid', b'goal_id.uuid[0] = 1',
            said='unknown_classes'),
    Hostile('h_name_space', 'events', b'CFT_ACTION_NODE ', b'node = node',
            said='unknown_classes'),
    Hostile('h_name_bytes', 'status', b'CFT_ACTION_\xff\xfe', b'cft_status_table = 1',
            said='unknown_classes'),
    # Fast DDS's DDS-SQL compares the byte with 300, never equal.
    Hostile('h_sql_range', 'feedback', b'DDSSQL', b'goal_id.uuid[0] = 300', said=None,
            nothing=True),
    Hostile('h_sql_params', 'feedback', b'DDSSQL',
            b' OR '.join(b'goal_id.uuid[%d] = %%%d' % (i % 16, i) for i in range(100)),
            tuple(b'\xff%d' % i for i in range(100)), said=None),
    Hostile('h_sql_bytes', 'feedback', b'DDSSQL', b'goal_id.uuid[0] = \xff\xfe junk', said=None),
]
PLAIN = [Hostile(f'plain_{topic}', topic, b'', b'', said=None)
         for topic in ('feedback', 'status', 'events')]


def participant(spec: Hostile) -> str:
    """The hostile participant's participant for a resident reader of ``spec``.

    A writer sends a sample for several readers of one participant once, to no reader in
    particular, and every reader of that participant matched with the writer takes it: so a
    reader that may receive less than a plain one has a participant of its own, and the readers
    that the guard refuses (each receives every sample) share one, apart from the plain readers.
    """
    return 'plain' if not spec.filter_class else 'refused' if spec.said else spec.name


def hexed(data: bytes) -> str:
    return data.hex() if data else '-'


def build() -> Path:
    """The hostile participant, built once per source (:mod:`harness.native_cache`).

    :raises native_cache.BuildUnavailable: no C++ compiler, no Fast DDS headers in this Python's
        prefix, or a failed build.
    """
    compiler = shutil.which('c++') or shutil.which('g++')
    include = Path(sys.prefix) / 'include'
    if compiler is None or not (include / 'fastdds' / 'dds' / 'domain').is_dir():
        raise native_cache.BuildUnavailable(
            "the hostile participant needs a C++ compiler and the Fast DDS headers of this "
            "Python's prefix")
    libraries = c_server.library_dirs(c_server.prefixes())
    command = [compiler, '-std=c++17', '-O1', f'-I{include}', str(SOURCE), '-o',
               native_cache.OUTPUT, '-rdynamic', *[f'-L{d}' for d in libraries],
               *[f'-Wl,-rpath,{d}' for d in libraries],
               *[f'-Wl,-rpath-link,{d}' for d in libraries], '-lfastrtps', '-lfastcdr', '-ldl']
    return native_cache.build('hostile_reader', 'hostile_reader', SOURCE, command,
                              'the hostile participant')


def start(program: Path, action: str, specs: list[Hostile]) -> Proc:
    """The hostile participant, with ``specs`` defined for ``action``'s topics."""
    topics = {'feedback': (f'rt{action}/_action/feedback', FEEDBACK_TYPE),
              'status': (f'rt{action}/_action/status', STATUS_TYPE),
              'events': ('rt/parameter_events', EVENTS_TYPE)}
    hostile = Proc('hostile', [str(program)], os.environ.copy())
    try:
        hostile.expect('READY', 30)
    except TimeoutError:
        hostile.stop()
        raise
    for spec in specs:
        topic, type_name = topics[spec.topic]
        hostile.send(' '.join(['spec', spec.name, topic, type_name, hexed(spec.filter_class),
                               hexed(spec.expression), *map(hexed, spec.parameters)]))
    return hostile


@pytest.fixture(scope='module')
def hostile_program() -> Path:
    try:
        return build()
    except native_cache.BuildUnavailable as error:
        pytest.skip(str(error))


class Run(NamedTuple):
    """What :func:`run` saw."""
    reports: dict[str, dict[str, Any]]        # the clients' RESULT, by mode
    received: dict[str, tuple[int, int, dict[str, int]]]  # reader -> (matched, samples, per UUID)
    stats: dict[str, Any]                     # the server's, at the end
    guard_lines: list[str]
    rss_kb: tuple[int, int]                   # after the first CHURN_FIRST readers, at the end
    removals: tuple[int, int]                 # remove_reader_filter calls expected, and made
    stolen: dict[str, int]                    # the thief's requests: sent, accepted, rejected
    server_alive: bool


def rss_kb(pid: int) -> int:
    with open(f'/proc/{pid}/status') as status:
        line = next(line for line in status if line.startswith('VmRSS:'))
    return int(line.split()[1])


def wait_removals(server: Proc, at_least: int, timeout: float = 60.0) -> int:
    """The server's remove_reader_filter calls, once at least ``at_least`` (or at ``timeout``)."""
    deadline = time.monotonic() + timeout
    while True:
        removed = server.request_json('stats', 'STATS')['guard_calls']['remove_reader_filter']
        if removed >= at_least or time.monotonic() > deadline:
            return removed
        time.sleep(0.2)


def churned(*calls: int) -> Counter[str]:
    """How many readers of each hostile spec the hostile participant's churn commands of ``calls``
    readers each create (each takes the specs in name order, from the first)."""
    names = sorted(h.name for h in HOSTILE if h.name.startswith('h'))
    return Counter(names[i % len(names)] for count in calls for i in range(count))


@pytest.fixture(scope='module')
def run(hostile_program: Path) -> Iterator[Run]:
    action = '/' + unique_name('cft_hostile')
    # Goals of 250 ms: the thief's requests reach the server while they run.
    server = action_server(action, 0.05, env=guard.environment(os.environ.copy()))
    processes: list[Proc] = [server]
    try:
        hostile = start(hostile_program, action, HOSTILE + PLAIN)
        processes.append(hostile)
        for spec in HOSTILE + PLAIN:
            opened = hostile.request(f'open {spec.name} {spec.name} {participant(spec)}',
                                     'OPENED', 30)
            assert opened.endswith(' ok'), (opened, hostile.tail())
        thief = helper_process('tests.helpers.goal_thief', [action], ready='')
        processes.append(thief)
        # The clients prove their goal service and feedback path before READY: a goal each.
        clients = {mode: helper_process('tests.helpers.fib_client', [action, mode, GOALS, ORDER],
                                        ready='') for mode in ('client', 'rclpy')}
        processes += clients.values()
        thief.expect('READY', 60)
        for client in clients.values():
            client.expect('READY', 60)
        base = server.request_json('stats', 'STATS')['guard_calls']['remove_reader_filter']
        reply = hostile.request(f'churn {CHURN_FIRST} {CHURN_WINDOW} {CHURN_PAUSE_MS} h',
                                'CHURNED', 120)
        assert reply == f'CHURNED {CHURN_FIRST} 0', reply
        # Each is matched, then removed, by one writer of the server (its feedback, status or
        # /parameter_events writer).
        expected = base + CHURN_FIRST
        wait_removals(server, expected)
        first = rss_kb(server.pid)
        for client in clients.values():
            client.send('go')
        rest = CHURN - CHURN_FIRST
        reply = hostile.request(f'churn {rest} {CHURN_WINDOW} {CHURN_PAUSE_MS} h', 'CHURNED', 180)
        assert reply == f'CHURNED {rest} 0', reply
        reports = {mode: json.loads(client.expect('RESULT', 90).split(' ', 1)[1])
                   for mode, client in clients.items()}
        expected = base + CHURN
        removed = wait_removals(server, expected) - base
        last = rss_kb(server.pid)
        received = {}
        for spec in HOSTILE + PLAIN:
            _, _, matched, samples, per_uuid = hostile.request(
                f'count {spec.name}', f'COUNT {spec.name} ').split(' ', 4)
            received[spec.name] = (int(matched), int(samples), json.loads(per_uuid))
        stolen = thief.request_json('report', 'STOLEN')
        stats = server.request_json('stats', 'STATS')
        alive = server.poll() is None
        lines = [line for line in server.lines if line.startswith('[cft_action guard')]
        yield Run(reports, received, stats, lines, (first, last), (expected - base, removed),
                  stolen, alive)
    finally:
        stop_all(reversed(processes))


def test_the_server_serves_every_other_client_exactly(run: Run) -> None:
    assert run.server_alive
    for mode, report in run.reports.items():
        assert report['results'] == GOALS and report['complete_goals'] == GOALS, (mode, report)
        assert report['own_received'] == GOALS * ORDER and report['misrouted'] == 0, (mode, report)
        assert report['stale_handles'] == 0, (mode, report)  # every status reached the client
    library = run.reports['client']
    # Nothing foreign reached the library client's reader: the writer filtered for it.
    assert library['taken'] - library['proof_taken'] == GOALS * ORDER, library
    assert library['dropped'] == 0 and library['filtered_in'] == 'writer', library


def test_the_guard_says_once_what_it_refused(run: Run) -> None:
    counts = run.stats['guard_filter']
    created = churned(CHURN_FIRST, CHURN - CHURN_FIRST)
    for kind in ('refused', 'unknown_classes'):
        # Each reader once per writer of the server that matched it (one: feedback, status or
        # /parameter_events), the resident readers and the churned ones.
        expected = sum(1 + created[h.name] for h in HOSTILE if h.said == kind)
        assert counts[kind] == expected, (kind, counts)
    said = [[line for line in run.guard_lines if words in line]
            for words in ('refused a remote reader', 'is none of the library',
                          'another participant had requested')]
    assert [len(lines) for lines in said] == [1, 1, 1], run.guard_lines
    assert sorted(sum(said, [])) == sorted(run.guard_lines), run.guard_lines
    # What the remote reader sent is quoted with its bytes escaped.
    assert all(line.isprintable() for line in run.guard_lines), run.guard_lines
    assert counts['mismatches'] == 0, counts


def test_a_request_for_anothers_goal_takes_nothing(run: Run) -> None:
    """The thief's requests (every goal of both clients, and their proofs) are rejected, and the
    guard keeps each goal's status with the client that requested it (the clients' stale_handles
    above): a later request for the same UUID from another participant is contested."""
    assert run.stolen['sent'] >= 2 * GOALS and run.stolen['accepted'] == 0, run.stolen
    assert run.stats['guard_status']['contested'] >= run.stolen['rejected'] > 0, (
        run.stolen, run.stats['guard_status'])


def test_a_hostile_reader_gets_what_a_plain_reader_gets_or_nothing(run: Run) -> None:
    """Feedback: each goal of the clients' run whole, as the plain reader gets it (reliable, the
    server keeps every sample), or none. Status: some, or none (a keep-last 1 writer replaces a
    sample that a reader has not acknowledged yet, plain readers' too, so counts may differ)."""
    goals = {uuid for report in run.reports.values() for uuid in report['goal_ids']}
    plain = {uuid: n for uuid, n in run.received['plain_feedback'][2].items() if uuid in goals}
    assert sorted(plain.values()) == [ORDER] * len(goals) == [ORDER] * 2 * GOALS, plain
    assert run.received['plain_status'][1] > 0, run.received['plain_status']
    for spec in HOSTILE:
        _, samples, per_uuid = run.received[spec.name]
        if spec.topic == 'feedback':
            got = {uuid: n for uuid, n in per_uuid.items() if uuid in goals}
            assert got == ({} if spec.nothing else plain), (spec.name, run.received[spec.name])
        elif spec.topic == 'status':
            assert (samples == 0) == spec.nothing, (spec.name, run.received[spec.name])
        # /parameter_events: the clients' nodes announce theirs as they start, matched or not


def test_the_servers_memory_stays_flat_over_1000_hostile_readers(run: Run) -> None:
    expected, removed = run.removals
    assert removed >= expected, run.removals  # the server saw every reader go
    if 'libasan' in os.environ.get('LD_PRELOAD', ''):
        pytest.skip("under AddressSanitizer (make test-asan), whose quarantine holds freed memory")
    first, last = run.rss_kb
    assert last <= first * RSS_GROWTH, f'RSS {first} kB after {CHURN_FIRST} readers, {last} kB ' \
                                       f'after {CHURN}'
