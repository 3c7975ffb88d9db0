"""`cft-action action list|info`: the real CLI as a subprocess, against a guarded and an unguarded
server (:mod:`harness.server`, both nodes named ``cft_fib_server``), with filtered and plain
clients (:mod:`harness.client`)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import Any

import pytest

from cft_action import guard
from harness.proc import Proc, python_module, stop_all
from harness.ros import unique_name

CLI = [sys.executable, '-m', 'cft_action.cli', 'action']
TYPE = 'test_msgs/action/Fibonacci'


# A new participant finds the others through its initial announcements, sent at once to the first 32
# participant ports of localhost (rmw_fastrtps' LOCALHOST range), and each answers with its own at
# once (Fast DDS 2.14's SPDP writer sends its state to a newly matched reader): the CLI's default
# spin (4 s) covers that and the endpoints' exchange with room to spare.
def _cli_runs(runs: dict[str, tuple[str, ...]]) -> dict[str, str]:
    """Run the CLI with each of ``runs``' arguments at once. Returns the output of each."""
    started = {key: subprocess.Popen([*CLI, *args], stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
               for key, args in runs.items()}
    outputs: dict[str, str] = {}
    for key, proc in started.items():
        try:
            out, err = proc.communicate(timeout=60)
        finally:
            proc.kill()
        assert proc.returncode == 0, err
        outputs[key] = out
    return outputs


@pytest.fixture
def graph():
    """``(guarded action, unguarded action)``: a guarded server with the clients ``/filtered_a``
    and ``/plain_a``, an unguarded one with ``/filtered_b``, each client past a completed goal."""
    guarded_action, unguarded_action = '/' + unique_name('cli_g'), '/' + unique_name('cli_u')
    procs = []
    try:
        for action, env in ((guarded_action, guard.environment()),
                            (unguarded_action, os.environ.copy())):
            procs.append(Proc(f'server {action}',
                              python_module('harness.server', action, 0.1, '--depth', 'all'), env))
        for action, config, node in ((guarded_action, 'client', 'filtered_a'),
                                     (guarded_action, 'rclpy', 'plain_a'),
                                     (unguarded_action, 'client', 'filtered_b')):
            procs.append(Proc(node, python_module('harness.client', action, config, 1, 1, 10, 0,
                                                  '--ros-args', '-r', f'__node:={node}'),
                              os.environ.copy()))
        for proc in procs:
            proc.expect('READY', 60)
        yield guarded_action, unguarded_action
    finally:
        stop_all(procs)


def _client(node: str, filtered_in: str, filter_class: str) -> dict[str, Any]:
    return {'node': node, 'types': [TYPE], 'feedback_filtered_in': filtered_in,
            'feedback_filter_classes': [filter_class]}


def test_action_list_and_info(graph):
    guarded_action, unguarded_action = graph
    out = _cli_runs({'guarded': ('info', guarded_action, '--json'),
                     'unguarded': ('info', unguarded_action, '--json'),
                     'text': ('info', guarded_action, '-t'),
                     'list': ('list', '-t')})
    assert json.loads(out['guarded']) == {
        'action': guarded_action,
        'clients': [_client('/filtered_a', 'writer', 'CFT_ACTION_UUID'),
                    _client('/plain_a', 'none', '')],
        'servers': [{'node': '/cft_fib_server', 'types': [TYPE], 'guard': True}]}
    assert json.loads(out['unguarded']) == {
        'action': unguarded_action,
        'clients': [_client('/filtered_b', 'reader', 'CFT_ACTION_UUID')],
        'servers': [{'node': '/cft_fib_server', 'types': [TYPE], 'guard': False}]}
    # The text, as `ros2 action info -t` prints it, with the two columns.
    assert out['text'].splitlines() == [
        f'Action: {guarded_action}',
        'Action clients: 2',
        f'    /filtered_a [{TYPE}] (feedback filtered in: writer)',
        f'    /plain_a [{TYPE}] (feedback filtered in: none)',
        'Action servers: 1',
        f'    /cft_fib_server [{TYPE}] (guard: yes)'], out['text']
    for action in graph:
        assert f'{action} [{TYPE}]' in out['list'].splitlines(), out['list']


def test_action_info_of_an_invalid_name():
    done = subprocess.run([*CLI, 'info', 'not a name', '--spin-time', '0'], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 1 and 'is invalid' in done.stderr, done
