"""Shared test machinery: the child processes of the tests, each in its own Python process.

A ROS session in the test process is :class:`harness.ros.RosSession`.
"""

from __future__ import annotations

import ctypes
import importlib.metadata
import json
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, NamedTuple, Optional, Sequence

import pytest
import rclpy
from test_msgs.action import Fibonacci

from cft_action import guard
from harness.crash import fastdds_library, live_backtrace
from harness.proc import Proc, python_module, stop_all
from harness.ros import RosSession, unique_name


def helper_process(module: str, args: Sequence[object] = (), *, env: Optional[dict] = None,
                   ready: str = 'READY', timeout: float = 30.0) -> Proc:
    """A helper module (``tests.helpers.NAME``, ``harness.NAME``) in its own Python process.

    It is driven by lines on stdin and stdout. Waits for its ``ready`` line (none if empty); the
    caller stops it.
    """
    argv = python_module(module, *args)
    return _started(Proc(module, argv, env or os.environ.copy()), ready, timeout)


def action_server(action: str, period: float, *, env: Optional[dict] = None,
                  late_feedback: float = 0.0, mute_cancel: bool = False,
                  feedback_depth: Optional[int] = None, result_pad: int = 0,
                  hold_goals: int = 0, timeout: float = 30.0) -> Proc:
    """The project's Fibonacci action server (:mod:`harness.server`) with keep-all queues.

    rclpy's default depth of 10 drops requests when many clients send goals at once (measured:
    4 of 15 goals lost with 3 clients), and any keep-last queue drops when a client on a loaded
    machine lags: these tests are about filtering, so every queue keeps all. ``late_feedback``
    and ``mute_cancel``: see the server's ``--late-feedback`` and ``--mute-cancel``;
    ``feedback_depth``: the feedback writer alone keeps that many (``--feedback-depth``);
    ``result_pad``: int32 elements appended to each result (``--result-pad``); ``hold_goals``:
    see ``--hold-goals``.
    """
    argv = python_module('harness.server', action, period, '--depth', 'all',
                         '--late-feedback', late_feedback,
                         *(['--mute-cancel'] if mute_cancel else []),
                         *(['--feedback-depth', feedback_depth] if feedback_depth else []),
                         *(['--result-pad', result_pad] if result_pad else []),
                         *(['--hold-goals', hold_goals] if hold_goals else []))
    return _started(Proc('server', argv, env or os.environ.copy()), 'READY', timeout)


def _started(proc: Proc, ready: str, timeout: float) -> Proc:
    if ready:
        try:
            proc.expect(ready, timeout)
        except TimeoutError:
            proc.stop()
            raise
    return proc


def fastdds_header_probe(source: str, tmp_path: Path) -> list[int]:
    """Compile a C++ ``source`` against the Fast DDS headers the guard was built from, run it, and
    return the integers it prints: the layouts that the guard assumes, as those headers define them.

    Skips the test where there is no C++ compiler, or no Fast DDS headers to compile against.
    """
    library = ctypes.CDLL(guard.library_path(), mode=os.RTLD_LOCAL)
    library.cft_guard_layout_includes.restype = ctypes.c_char_p
    recorded = [d for d in library.cft_guard_layout_includes().decode().split(os.pathsep) if d]
    # A first install into a fresh venv builds in pip's isolated environment, whose copy of the
    # wheels' headers is gone since; the same wheel's headers are then in this venv, which the
    # build listed after it (or, if it did not, sys.prefix/include). Headers of another build
    # than the guard's would make the comparison fail, not pass.
    includes = [d for d in recorded if Path(d).is_dir()] or [str(Path(sys.prefix) / 'include')]
    compiler = shutil.which('c++') or shutil.which('g++')
    if compiler is None or not recorded or not any(
            (Path(d) / 'fastrtps' / 'config.h').is_file() for d in includes):
        pytest.skip('needs a C++ compiler and the Fast DDS headers the guard was built from')
    source_file = tmp_path / 'probe.cpp'
    source_file.write_text(source)
    binary = tmp_path / 'probe'
    # Linked to the wheels' Fast DDS for its static constants; the libraries it needs in turn
    # are found at run time through this process's LD_LIBRARY_PATH (ros-wheels-bootstrapper's).
    subprocess.run([compiler, '-std=c++17', '-Wno-invalid-offsetof',
                    *[f'-I{d}' for d in includes], str(source_file), '-o', str(binary),
                    f'-L{Path(sys.prefix) / "lib"}', '-lfastrtps', '-lfastcdr',
                    '-Wl,--unresolved-symbols=ignore-in-shared-libs'],
                   check=True, capture_output=True, timeout=120)
    return [int(v) for v in subprocess.run([str(binary)], check=True, capture_output=True,
                                           text=True, timeout=30).stdout.split()]


def loaded_fastdds_version() -> Optional[tuple[int, int, int]]:
    """The version of the Fast DDS library this process loads, or None when it cannot tell.

    From the file's real name (a stack's ``libfastrtps.so.2.14.6``), or, for the ROS wheels' copy
    in this venv (named only ``libfastrtps.so.2.14``), from the ``ros-fastrtps`` wheel's version
    (Fast DDS 3's wheel, ``ros-fastdds`` 3.2.3, holds Fast DDS 3.2.2: None there).
    """
    real = os.path.realpath(fastdds_library())
    match = re.search(r'lib(?:fastrtps|fastdds)\.so\.(\d+)\.(\d+)\.(\d+)', real)
    if match is None and Path(real).parent == Path(sys.prefix, 'lib').resolve() and \
            'libfastrtps' in real:
        match = re.match(r'(\d+)\.(\d+)\.(\d+)', importlib.metadata.version('ros-fastrtps'))
    if match is None:
        return None
    major, minor, micro = (int(v) for v in match.groups())
    return major, minor, micro


def round_trip(ros: RosSession, client: Any, tries: int = 10,
               wait: Optional[Callable[[Callable[[], bool], float], bool]] = None) -> bool:
    """Complete one order-0 goal (no feedback), resending while the service endpoints match.

    wait_for_server sees the server in the graph; a goal response written before the server's
    response writer matched this client's reader is lost for good (volatile), as with rclpy:
    rmw_fastrtps waits 100 ms for that match, then drops the reply ("failed to send response
    (timeout): client will not receive response"), e.g. while the server is still discovering the
    readers of 40 other clients.

    :param wait: how to wait for the response, ``ros.spin_until`` unless an executor already spins
        in another thread.
    """
    for _ in range(tries):
        future = client.send_goal_async(Fibonacci.Goal(order=0))
        if (wait or ros.spin_until)(future.done, 2):
            return future.result().accepted
    return False


def node_waiter(node: Any) -> Callable[[Callable[[], bool], float], bool]:
    """``wait(predicate, timeout)`` for a process with one node and no executor of its own (the
    client processes of tests/helpers): spins the node until ``predicate()`` holds, bounded."""
    def wait(predicate: Callable[[], bool], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                return predicate()
            rclpy.spin_once(node, timeout_sec=0.05)
        return True
    return wait


def connect_helper_client(node: Any, client: Any) -> bool:
    """In a client process of tests/helpers: wait for the server and prove the feedback path.

    Prints ``NO SERVER`` or ``NO FEEDBACK <why>`` for the test to read and returns False when
    either does not come; True when the client may say ``READY``.
    """
    if not client.wait_for_server(timeout_sec=20):
        print('NO SERVER', flush=True)
        return False
    try:
        prove_feedback_path(node_waiter(node), client)
    except AssertionError as error:
        print(f'NO FEEDBACK {error}', flush=True)
        return False
    return True


def prove_feedback_path(wait: Callable[[Callable[[], bool], float], bool], client: Any,
                        tries: int = 10) -> int:
    """Send order-1 goals until one's feedback reaches ``client``; return how many were sent.

    Every test that counts feedback calls this first: ``make_client`` of test_action_client does
    it for its clients, and the client processes of tests/helpers before they say ``READY``. A
    goal response proves the goal service, not the feedback path: the server's feedback writer
    discovers the client's reader on its own, and a feedback message published before that match
    is gone, as for plain rclpy. Each goal's result is asked for only once its feedback arrived
    (or did not within 2 s), so that its feedback is not dropped for racing the result; when this
    returns, every goal it sent has its result. Counters read afterwards include these goals: a
    test counts from a snapshot taken after this call.

    :param wait: ``wait(predicate, timeout)``, which spins the client's node (``ros.spin_until``)
        unless an executor already spins it in another thread; returns whether ``predicate`` held.
    """
    answered = 0
    for sent in range(1, tries + 1):
        received: list[Any] = []
        future = client.send_goal_async(Fibonacci.Goal(order=1), feedback_callback=received.append)
        if not wait(future.done, 2):
            continue  # a goal response dropped before the services matched (round_trip)
        answered += 1
        handle = future.result()
        assert handle.accepted, 'the server rejected an order-1 goal'
        arrived = wait(lambda received=received: bool(received), 2)
        result = handle.get_result_async()
        assert wait(result.done, 20), 'an accepted order-1 goal got no result in 20 s'
        if arrived:
            return sent
    state = getattr(client, 'feedback_filter_state', None)
    raise AssertionError(f'no feedback reached the client in {tries} goals ({answered} answered); '
                         f'its filter: {state}')


def server_evidence(server: Proc) -> str:
    """What a server was doing when a client's goals went unanswered, for an assertion's message.

    Its output, its goal-request counters (did requests reach it, did its responses fail to go
    out) and, from gdb, what each of its threads was doing: the evidence of a one-off failure
    that a rerun would not show.
    """
    try:
        stats = server.request('stats', 'STATS', timeout=10)
    except TimeoutError as error:
        stats = f'(no STATS in 10 s: {error})'
    threads = live_backtrace(server.pid, frames=12) if server.poll() is None else None
    return f'{server.tail()}\n{stats}\n--- threads ---\n{threads}'


def send(ros: RosSession, client: Any, order: int, **kwargs: Any) -> Any:
    """Send a goal of ``order`` and return its goal handle, once answered."""
    future = client.send_goal_async(Fibonacci.Goal(order=order), **kwargs)
    assert ros.spin_until(future.done, 20)
    return future.result()


def result_of(ros: RosSession, goal_handle: Any) -> Any:
    """The result response of an accepted goal."""
    future = goal_handle.get_result_async()
    assert ros.spin_until(future.done, 30)
    return future.result()


ROOT = Path(__file__).resolve().parent.parent
# What the package's build reads: setup.py builds the extensions, pyproject.toml has the metadata
# (and reads README.md), package.xml and resource/ make it an ament_python package.
PACKAGE_FILES = ('setup.py', 'pyproject.toml', 'package.xml', 'README.md', 'resource')


def copy_package(destination: Path) -> None:
    """Copy what building the package reads into ``destination``: a clone's sources, without
    what an editable install built in place."""
    destination.mkdir(parents=True)
    for name in PACKAGE_FILES:
        source = ROOT / name
        if source.is_dir():
            shutil.copytree(source, destination / name)
        else:
            shutil.copy2(source, destination / name)
    shutil.copytree(ROOT / 'cft_action', destination / 'cft_action',
                    ignore=shutil.ignore_patterns('*.so', '__pycache__'))


def prove_parameter_events(ros: RosSession, handler: Any, nodes: Proc, names: Sequence[str],
                           timeout: float = 15.0) -> str:
    """Return once an event of each of ``names`` got through the handler's current filter.

    The proof of the event path for every test that counts parameter events: a callback of a
    handler that only was created, or whose filter only was changed, proves nothing, since the
    writers match the reader, and learn of a filter change, by discovery, and until then apply
    the previous filter. ``nodes`` is a :mod:`harness.param_nodes` process. It adds a ``sync``
    parameter callback on each name, whose first call proves that the node's writer has the
    current filter; that must not change the filter (asserted), so with a filter on the watched
    nodes (mode ``'nodes'``) each name must already be watched. Returns what it took, for the
    message of a later failure.
    """
    # Round r sets sync to 1..r and waits for the event of r: the writer delivers in order, so
    # once the last set's event is in, every earlier one has come or never will (filtered by the
    # writer's previous filter). No proof event can then arrive during the caller's count.
    last: dict[str, int] = {}
    handles = [handler.add_parameter_callback(
        'sync', n, lambda p, n=n: last.__setitem__(n, p.value.integer_value)) for n in names]
    updates = handler.parameter_event_filter_state.updates
    started = time.monotonic()
    rounds = 0
    asked: dict[str, int] = {}
    try:
        deadline = started + timeout

        def proven() -> bool:
            return all(n in asked and last.get(n) == asked[n] for n in names)

        while not proven() and time.monotonic() < deadline:
            rounds += 1
            for name in names:
                if name not in asked or last.get(name) != asked[name]:
                    asked[name] = rounds
                    nodes.request(f'set {name} sync {rounds}', 'SET')
            ros.spin_until(proven, timeout=0.3)
        missing = {n for n in names if last.get(n) != asked.get(n)}
        assert not missing, f'no event from {missing} within {timeout} s'
    finally:
        for handle in handles:
            handler.remove_parameter_callback(handle)
    assert handler.parameter_event_filter_state.updates == updates, 'the proof changed the filter'
    return (f'the event path of {sorted(names)} proven in {rounds} rounds, '
            f'{time.monotonic() - started:.3f} s')


#: UDP only (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` with ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``:
#: with ``LOCALHOST`` rmw_fastrtps adds shared memory, which carries the data past any capture).
UDP_ONLY = {'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}


class WireRun(NamedTuple):
    """What :func:`clients_on_the_wire` saw: the clients' reports, in order; what ``capture``
    returned for the captured writers; the server's stats at ``go`` and at the end (its
    ``writers`` name the GUIDs of its feedback, status and reply writers); every line the server
    printed."""
    reports: list[dict[str, Any]]
    captured: dict[int, Any]
    stats_at_go: dict[str, Any]
    stats_after: dict[str, Any]
    server_lines: list[str]

    def counted(self, part: str) -> dict[str, int]:
        """The server's counters ``part`` of its stats (e.g. ``guard_heartbeats``) over the goals:
        at the end less at ``go``."""
        before = self.stats_at_go[part]
        return {key: value - before[key] for key, value in self.stats_after[part].items()}


def clients_on_the_wire(clients: Sequence[Sequence[object]], capture: Callable[..., dict],
                        writers: Sequence[str] = ('feedback',), *, guarded: bool = True,
                        server_env: Optional[dict] = None, feedback_depth: Optional[int] = None,
                        result_pad: int = 0, together: bool = False,
                        release_after: Optional[float] = None,
                        client_envs: Sequence[dict] = ()) -> WireRun:
    """Run a server (guarded or not) and one client process (tests/helpers/fib_client.py) per
    entry of ``clients`` (its arguments after the action: mode, goals, order[, writer_filtering]),
    all on UDP only; capture on loopback with ``capture(interface, {writer GUIDs}, stop,
    listening)`` (from :mod:`harness.capture`, root only) the traffic of the server's ``writers``
    (names of harness.server's STATS ``writers``) while the clients' goals run. ``together``
    starts the clients at once instead of one after another. ``release_after``: the server holds
    every goal of ``go`` after its first feedback until that many seconds after it.
    ``client_envs``: variables of each client's own, in the order of ``clients`` (e.g. its SROS2
    enclave's, :class:`harness.keystore.Keystore`); ``server_env`` the server's."""
    env = {**os.environ, **UDP_ONLY}
    own = list(client_envs) or [{}] * len(clients)
    action = '/' + unique_name('cft_wire')
    server_environment = {**env, **(server_env or {})}
    server = action_server(action, 0.01, feedback_depth=feedback_depth, result_pad=result_pad,
                           env=guard.environment(server_environment) if guarded
                           else server_environment)
    stop, listening = threading.Event(), threading.Event()
    captured: dict[int, Any] = {}
    processes = []
    sniffer = None
    try:
        named = server.request_json('stats', 'STATS')['writers']
        guids = {bytes.fromhex(named[name][0]) for name in writers}
        # Each client proves its goal service and feedback path before READY; the capture starts
        # after that, so it holds the measured goals' traffic only.
        processes = [helper_process('tests.helpers.fib_client', [action, *arguments],
                                    env={**env, **extra}, ready='' if together else 'READY')
                     for arguments, extra in zip(clients, own, strict=True)]
        for process in processes if together else ():
            process.expect('READY', 60)
        sniffer = threading.Thread(target=lambda: captured.update(
            capture('lo', guids, stop, listening)))
        sniffer.start()
        assert listening.wait(10)
        at_go = server.request_json('stats', 'STATS')
        if release_after is not None:
            server.send('hold')
        for process in processes:
            process.send('go')
        if release_after is not None:
            time.sleep(release_after)
            server.send('release')
        reports = [json.loads(process.expect('RESULT', timeout=90).split(' ', 1)[1])
                   for process in processes]
        after = server.request_json('stats', 'STATS')
        assert server.poll() is None, f'server died\n{server.tail()}'
    finally:
        stop.set()
        if sniffer is not None:
            sniffer.join(timeout=10)  # it fills captured as it ends
        stop_all(processes)
        server.stop()
    return WireRun(reports, captured, at_go, after, list(server.lines))


def feedback_on_the_wire(clients: Sequence[tuple[str, str]], capture: Callable[..., dict],
                         goals: int, order: int, *, server_env: Optional[dict] = None,
                         feedback_depth: Optional[int] = None) -> WireRun:
    """:func:`clients_on_the_wire` for a guarded server's feedback writer: one client per (mode,
    writer_filtering), each sending ``goals`` goals of ``order`` feedback messages.

    The clients start together: each proves its feedback path before ``READY``, and nothing is
    captured or counted before all are ready, so their discoveries of the server (up to Fast
    DDS's 3 s announcement period each) may overlap."""
    return clients_on_the_wire([(mode, goals, order, filtering) for mode, filtering in clients],
                               capture, server_env=server_env, feedback_depth=feedback_depth,
                               together=True)
