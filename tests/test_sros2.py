"""DDS Security (SROS2): a guarded server and the library's clients, each in an enclave of its own.

Runs where the loaded Fast DDS was built with security (apt's 2.14.6: ``make compat
COMPAT_STACKS=apt-2.14.6``; Lyrical's 3.6.2: ``make compat-kilted``); the wheels' Fast DDS has none
(``HAVE_SECURITY 0``), so in ``make test`` every test here skips, saying so. Each test makes its
keystore in rcl's layout (:class:`harness.keystore.Keystore`), with a governance that protects
discovery, liveliness, whole messages, submessages and payloads at ENCRYPT, or at SIGN, and runs
every process Enforce in an enclave of its own. At SIGN the payloads are not signed: Fast DDS
2.14.6's readers refuse signed payloads of their own accord (``Error decoding encoded payload``;
measured with plain rclpy alone: no status sample came, and feedback stopped after 27 or 35 of 50
messages per goal with two plain clients; docs/COMPATIBILITY.md), which no client can help.

What is promised is what holds without security: every goal's result, feedback, status and replies
reach their client and no other, filtered on the server's writer. On the wire (a raw socket on
loopback, root, UDP only) a protected message names no writer: what is counted per client's port
is the datagrams the server's participant sent it (:func:`harness.capture.protected_by_port`), and
under SIGN, where submessages are readable, the feedback samples too. A participant whose
permissions deny the action's topics cannot create a reader of them, and one without credentials
receives nothing of the server.
"""

from __future__ import annotations

import json
import os
import uuid
from pathlib import Path
from typing import Iterator, Optional

import pytest

from cft_action import guard
from harness.capture import protected_by_port
from harness.crash import fastdds_library
from harness.keystore import Keystore
from harness.proc import stop_all
from harness.ros import unique_name
from tests.support import WireRun, action_server, clients_on_the_wire, helper_process

#: SecurityManager::cancel_init(), which only a Fast DDS built with SECURITY=ON exports: 2.14's and
#: 3.x's name.
SECURITY_SYMBOLS = ('_ZN8eprosima8fastrtps4rtps8security15SecurityManager11cancel_initEv',
                    '_ZN8eprosima7fastdds4rtps8security15SecurityManager11cancel_initEv')
#: Whether the loaded Fast DDS is a 3.x (the guard's Fast DDS 3 layer; no merged personal GAPs).
FASTDDS3 = 'libfastdds.so.3' in fastdds_library()


def security_missing() -> Optional[str]:
    """Why this process's Fast DDS cannot run with security, or None when it can."""
    path = fastdds_library()
    if not Path(path).is_file():
        return f'no Fast DDS 2.14 to run with security ({path})'
    # Read from the file, not loaded: this runs at collection, and the suite's other tests load
    # Fast DDS when and as rclpy does (the reader lock interposes its members).
    content = Path(path).read_bytes()
    if not any(symbol.encode() in content for symbol in SECURITY_SYMBOLS):
        return (f'{path} was built without security (HAVE_SECURITY 0, as the wheels\' is): '
                '`make compat COMPAT_STACKS=apt-2.14.6` and `make compat-kilted` run these tests')
    return None


_MISSING = security_missing()
pytestmark = pytest.mark.skipif(_MISSING is not None, reason=_MISSING or '')
needs_root = pytest.mark.skipif(os.geteuid() != 0, reason='a raw socket needs root')

GOALS, ORDER = 2, 40
#: Datagrams a client of the library may get besides its own feedback: its goals' status samples
#: (and those owed), goal and result replies, HEARTBEATs, GAPs, and repairs.
SLACK = 40


#: (protection of messages and submessages, of payloads): the governances the tests run under.
GOVERNANCES = {'ENCRYPT': ('ENCRYPT', 'ENCRYPT'), 'SIGN': ('SIGN', 'NONE')}


@pytest.fixture(scope='module', params=sorted(GOVERNANCES))
def keystore(request: pytest.FixtureRequest,
             tmp_path_factory: pytest.TempPathFactory) -> Iterator[Keystore]:
    """A keystore whose governance encrypts everything, then one that signs all but payloads."""
    root = tmp_path_factory.mktemp(f'keystore_{request.param}')
    yield Keystore(root, *GOVERNANCES[request.param])


def enclave(keystore: Keystore, role: str, deny: tuple[str, ...] = ()) -> dict[str, str]:
    """A new enclave of ``role`` in ``keystore``, and the environment that runs a process in it."""
    return keystore.enclave(f'/cft/{role}_{uuid.uuid4().hex[:8]}', deny)


def secured_run(keystore: Keystore, clients: tuple[tuple[object, ...], ...],
                **options: object) -> WireRun:
    """:func:`tests.support.clients_on_the_wire` with the guarded server and each client in its
    own enclave, capturing what the server's participant sends each port."""
    return clients_on_the_wire(
        clients, protected_by_port, ('feedback',),
        server_env={**enclave(keystore, 'server'), **options.pop('server_env', {})},  # type: ignore[dict-item]
        client_envs=[enclave(keystore, f'client{i}') for i in range(len(clients))],
        **options)  # type: ignore[arg-type]


def counted(keystore: Keystore) -> str:
    """What is counted of a port's datagrams (:func:`harness.capture.protected_by_port`): under
    SIGN those that name the feedback writer; under ENCRYPT, where none can be read, all the
    server's."""
    return 'named' if keystore.protection == 'SIGN' else 'datagrams'


def ports_by_traffic(run: WireRun, clients: int, key: str) -> list[dict[str, int]]:
    """The counts of the ``clients`` ports with the most ``key``, most first (the other ports are
    the participants' discovery ports)."""
    ports = sorted(run.captured.values(), key=lambda seen: seen[key], reverse=True)
    assert len(ports) >= clients, run.captured
    return ports[:clients]


MIXED = (('client', GOALS, ORDER), ('goals', GOALS, ORDER), ('rclpy', GOALS, ORDER))


@needs_root
def test_each_enclave_gets_its_own_goals_filtered_on_the_writer(keystore: Keystore) -> None:
    """Two clients of the library (modes ``client`` and ``goals``) and a plain one, each in its
    enclave, against a guarded server: every goal's feedback complete and no other's, every result,
    every handle SUCCEEDED (status), the others' replies and statuses withheld by the server's
    writers, the library's clients filtered in the writer. On the wire the library's clients' ports
    get their own feedback and their personal GAPs and HEARTBEATs (beside a plain reader those
    come alone: tests/test_heartbeats.py), fewer datagrams than the feedback writes."""
    run = secured_run(keystore, MIXED, together=True, release_after=1.5)
    for (mode, _, _), report in zip(MIXED, run.reports):
        assert report['results'] == GOALS and report['stale_handles'] == 0, (mode, report)
        assert report['misrouted'] == 0, (mode, report)
        if mode != 'rclpy':  # (plain rclpy drops a goal's late feedback once its result is in)
            assert report['complete_goals'] == GOALS, (mode, report)
            assert report['filtered_in'] == 'writer', (mode, report)
            # the others' replies never came: the guard filtered them in the server's writers
            # (the client's response filter, which counts them, reads Fast DDS 2.14 layouts)
            assert report['responses_dropped'] == 0, (mode, report)
            assert FASTDDS3 or report['responses_passed'] > 0, (mode, report)
    status, replies = run.counted('guard_status'), run.counted('guard_replies')
    assert status['withheld'] > 0 and status['malformed'] == status['unknown'] == 0, status
    assert replies['withheld'] > 0 and replies['implausible'] == 0, replies
    writes, own = len(MIXED) * GOALS * ORDER, GOALS * ORDER
    key = counted(keystore)
    # (Only upper bounds: the capture, a thread of this process, may miss datagrams on a loaded
    # machine; the clients' reports say what arrived.)
    plain, *filtered = ports_by_traffic(run, len(MIXED), key)
    for seen in filtered:
        assert 0 < seen[key] <= min(2 * own + SLACK, writes - 1), run.captured
    for seen in (plain, *filtered):
        assert seen['srtps'] == seen['datagrams'], run.captured  # every one protected whole
    if keystore.protection == 'SIGN':  # readable: the feedback samples themselves
        for seen in filtered:
            assert 0 < seen['samples'] <= own + SLACK // 4, run.captured
    else:
        assert all(seen['named'] == seen['sec'] == 0 for seen in run.captured.values())


@needs_root
def test_personal_gaps_ride_in_the_data_under_protection(keystore: Keystore) -> None:
    """Two clients of the library alone on a writer of rclpy's feedback depth: each one's sample
    after the other's follows a run filtered out for it, whose GAP and HEARTBEAT the guard puts in
    the DATA's datagram (cft_action/native/guard/_guard_heartbeats.c, part 4). Under protection
    too: each port gets about a datagram per own sample, not two (:func:`counted`)."""
    goals, order = 4, 50
    clients = (('client', goals, order), ('client', goals, order))
    run = secured_run(keystore, clients, together=True, feedback_depth=10)
    for report in run.reports:
        assert report['complete_goals'] == goals and report['misrouted'] == 0, report
    counts = run.counted('guard_heartbeats')
    assert counts['gaps_merged'] > 0 and counts['merges_dropped'] == 0, counts
    # Unmerged, a datagram of its own before nearly every own sample: about twice as many.
    key, own = counted(keystore), goals * order
    for seen in ports_by_traffic(run, len(clients), key):
        assert 0 < seen[key] <= own + own // 3, (run.captured, counts)


def test_a_participant_denied_the_action_topics_receives_nothing(keystore: Keystore) -> None:
    """Beside a guarded server and a client of the library in their enclaves: a participant whose
    permissions deny the action's topics can create neither an ActionClient nor a reader of its
    feedback or status (rcl says why), and one without credentials sees no server and receives
    nothing, while the client gets all its feedback."""
    action = '/' + unique_name('cft_sros2')
    server = action_server(action, 0.01, env=guard.environment(
        {**os.environ, **enclave(keystore, 'server')}))
    procs = [server]
    try:
        client = helper_process('tests.helpers.fib_client', [action, 'client', GOALS, 100],
                                env={**os.environ, **enclave(keystore, 'client')}, timeout=60)
        procs.append(client)
        denied = helper_process('tests.helpers.sros2_probe', [action, 3.0], env={
            **os.environ, **enclave(keystore, 'denied', (f'*{action}/_action/*',))}, timeout=60)
        procs.append(denied)
        outsider = helper_process('tests.helpers.sros2_probe', [action, 3.0], timeout=60)
        procs.append(outsider)
        for proc in (client, denied, outsider):
            proc.send('go')
        got = {name: json.loads(proc.expect('RESULT', 90).split(' ', 1)[1])
               for name, proc in (('client', client), ('denied', denied), ('outsider', outsider))}
    finally:
        stop_all(procs)
    assert got['client']['complete_goals'] == GOALS, got
    assert set(got['denied']['refused']) == {'action_client', 'feedback', 'status'}, got
    assert got['denied']['feedback'] == got['denied']['status'] == 0, got
    assert got['outsider']['refused'] == {} and not got['outsider']['server'], got
    assert got['outsider']['feedback'] == got['outsider']['status'] == 0, got
