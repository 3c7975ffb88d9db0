# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Tests of the server guard: cft_action/native/guard/_guard.c, cft_action.guard and ``cft-action
guard``.

Three layers:
- the library and the command line (path, acceptance command, environment);
- the C logic against a stand-in Fast DDS built here (tests/helpers/guard_fake_fastdds.c): locking
  on the known version, calling straight through on an unknown one, late loading;
- the real stack: an rclpy publisher under the guard, and the churn scenario of Fast-DDS issue 4878
  (a server publishing feedback every 0.5 ms while a client changes its filter every 20 ms).

Every process a test starts runs in its own process and is killed by that test; every wait is
bounded.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import uuid
from pathlib import Path
from typing import Iterator

import pytest

from harness.domain import unused_domain

# A session conftest normally sets these; on its own this module still gets a domain of its own.
os.environ.setdefault('ROS_DOMAIN_ID', str(unused_domain()))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from cft_action import guard
from harness import crash, hazard
from harness.proc import Proc, python_module, stop_all

HELPERS = Path(__file__).resolve().parent / 'helpers'
SCENARIO = 'tests.helpers.guard_scenario'
GUARD_LINE = '[cft_action guard'
# What a guarded rclpy process reports: active on a known Fast DDS (2.14 on Jazzy, 3.2 on Kilted).
KNOWN_ACTIVE = ('STATUS True active: libfastrtps.so.2.14', 'STATUS True active: libfastdds.so.3.2')


def cft_action_command() -> list[str]:
    """The installed console script next to this interpreter, else the module."""
    script = Path(sys.executable).parent / 'cft-action'
    if script.is_file():
        return [str(script)]
    return [sys.executable, '-m', 'cft_action.cli']


def plain_env(**extra: str) -> dict[str, str]:
    """os.environ without the guard, in this session's domain, plus ``extra``."""
    return crash.plain_env(int(os.environ['ROS_DOMAIN_ID']), **extra)


@pytest.fixture
def procs() -> Iterator[list[Proc]]:
    """Processes started by a test; all of them are stopped when it ends, pass or fail."""
    started: list[Proc] = []
    yield started
    stop_all(started)


def start(procs: list[Proc], name: str, args: list[str], env: dict[str, str]) -> Proc:
    proc = Proc(name, args, env)
    procs.append(proc)
    return proc


def run(args: list[str], env: dict[str, str], timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run(args, env=env, capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL)


# --- the library and the command line -------------------------------------------------------------

def test_print_path_gives_the_built_library() -> None:
    result = run([*cft_action_command(), 'guard', '--print-path'], plain_env())
    assert result.returncode == 0, result.stderr
    path = result.stdout.strip()
    assert os.path.isfile(path), path
    assert os.path.samefile(path, guard.library_path())
    assert Path(path).parent == Path(guard.__file__).resolve().parent


def test_acceptance_is_active_only_under_the_guard() -> None:
    code = 'import cft_action.guard as g; print(g.is_active())'
    guarded = run([*cft_action_command(), 'guard', '--', sys.executable, '-c', code], plain_env())
    assert guarded.returncode == 0, guarded.stderr
    assert guarded.stdout.strip() == 'True', guarded.stdout + guarded.stderr
    assert GUARD_LINE not in guarded.stderr  # silent in the normal case

    unguarded = run([sys.executable, '-c', code], plain_env())
    assert unguarded.returncode == 0, unguarded.stderr
    assert unguarded.stdout.strip() == 'False', unguarded.stdout + unguarded.stderr


def test_environment_prepends_the_guard_once() -> None:
    path = guard.library_path()
    env = guard.environment({'LD_PRELOAD': '/opt/a.so /opt/b.so', 'X': '1'})
    assert env['LD_PRELOAD'] == f'{path}:/opt/a.so:/opt/b.so'
    assert env['X'] == '1'
    assert guard.environment(env)['LD_PRELOAD'] == env['LD_PRELOAD']
    assert guard.environment({})['LD_PRELOAD'] == path


def test_cli_errors() -> None:
    no_command = run([*cft_action_command(), 'guard'], plain_env())
    assert no_command.returncode == 2
    assert 'command' in no_command.stderr
    missing = run([*cft_action_command(), 'guard', '--', 'no-such-command-' + uuid.uuid4().hex],
                  plain_env())
    assert missing.returncode == 127
    assert 'command not found' in missing.stderr


def test_guard_passes_arguments_and_status_through() -> None:
    result = run([*cft_action_command(), 'guard', '--', sys.executable, '-c',
                  'import os, sys; print(os.environ["LD_PRELOAD"].split(":")[0]); '
                  'print(sys.argv[1:]); sys.exit(3)', '--print-path', 'x y'], plain_env())
    assert result.returncode == 3, result.stderr
    first, argv = result.stdout.splitlines()
    assert first == guard.library_path()
    assert argv == "['--print-path', 'x y']"


# --- the C logic against a stand-in Fast DDS ------------------------------------------------------

@pytest.fixture(scope='module')
def fake_fastdds(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """Build the stand-in library twice: as the known soname, and as an unknown one."""
    compiler = shutil.which('cc') or shutil.which('gcc')
    if compiler is None:
        pytest.skip('no C compiler to build the stand-in Fast DDS')
    out = tmp_path_factory.mktemp('fake_fastdds')
    built = {}
    for key, soname in (('known', 'libfastrtps.so.2.14'), ('unknown', 'libfastrtps.so.2.13')):
        (out / key).mkdir()
        target = out / key / soname
        subprocess.run([compiler, '-O2', '-shared', '-fPIC', f'-Wl,-soname,{soname}', '-o',
                        str(target), str(HELPERS / 'guard_fake_fastdds.c')],
                       check=True, timeout=120, capture_output=True)
        built[key] = str(target)
    main_c = out / 'linked_main.c'
    main_c.write_text(
        '#include <dlfcn.h>\n#include <stdio.h>\n'
        'int fake_write(void *w, int kind);\n'
        'int main(void) {\n'
        '  int r = fake_write((void *)0x1000, 2);\n'
        '  int (*state)(void) = (int (*)(void))dlsym(RTLD_DEFAULT, "cft_guard_state");\n'
        '  printf("%d %d\\n", r, state ? state() : -1);\n'
        '  return 0;\n}\n')
    built['linked_main'] = str(out / 'linked_main')
    subprocess.run([compiler, '-o', built['linked_main'], str(main_c), built['known'],
                    '-ldl'],
                   check=True, timeout=120, capture_output=True)
    cxx = shutil.which('c++') or shutil.which('g++')
    if cxx is not None:
        (out / 'throwing').mkdir()
        built['throwing'] = str(out / 'throwing' / 'libfastrtps.so.2.14')
        subprocess.run([cxx, '-O2', '-shared', '-fPIC', '-Wl,-soname,libfastrtps.so.2.14', '-o',
                        built['throwing'], str(HELPERS / 'guard_fake_throwing.cpp')],
                       check=True, timeout=120, capture_output=True)
    return built


def drive_fake(library: str, env: dict[str, str], *extra: str) -> tuple[dict, str]:
    result = run([sys.executable, str(HELPERS / 'guard_fake_driver.py'), library, '0.4', *extra],
                 env, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr
    return json.loads(result.stdout.strip().splitlines()[-1]), result.stderr


def test_fake_race_is_visible_without_the_guard(fake_fastdds: dict[str, str]) -> None:
    # The control: the stand-in does detect writes that overlap filter changes.
    report, _ = drive_fake(fake_fastdds['known'], plain_env())
    assert 'state' not in report
    assert report['writes'] > 0 and report['changes'] > 0
    assert report['overlaps'] > 0, report


def test_guard_serializes_writes_with_filter_changes(fake_fastdds: dict[str, str]) -> None:
    report, stderr = drive_fake(fake_fastdds['known'], guard.environment(plain_env()))
    assert report['state'] == 1 and report['active'] == 1, report
    assert report['reason'].startswith('active: libfastrtps.so.2.14'), report
    assert report['writes'] > 0 and report['changes'] > 0, report
    assert report['overlaps'] == 0, report
    assert report['wrong_returns'] == 0, report
    writes, infos, removals, _ = report['calls']
    assert writes == report['writes'] and infos + removals == report['changes'], report
    assert GUARD_LINE not in stderr  # nothing printed in the normal case


def test_guard_unlocks_a_writer_when_an_exception_unwinds_through_it(
        fake_fastdds: dict[str, str]) -> None:
    # Fast DDS is C++: a write that throws must not leave the writer's lock held, or the next
    # filter change (the discovery thread) waits forever, and participant shutdown with it.
    if 'throwing' not in fake_fastdds:
        pytest.skip('no C++ compiler to build the throwing stand-in')
    result = run([sys.executable, str(HELPERS / 'guard_fake_driver.py'), fake_fastdds['throwing'],
                  '--throw'], guard.environment(plain_env()), timeout=60)
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report == {'write_returned': [-1], 'remove_returned': True}, result.stderr


def test_guard_debug_output(fake_fastdds: dict[str, str]) -> None:
    report, stderr = drive_fake(fake_fastdds['known'],
                                guard.environment(plain_env(CFT_GUARD_DEBUG='1')))
    assert report['state'] == 1, report
    assert f'{GUARD_LINE}' in stderr and 'active: libfastrtps.so.2.14' in stderr, stderr


def test_unknown_version_calls_through_and_says_so_once(fake_fastdds: dict[str, str]) -> None:
    report, stderr = drive_fake(fake_fastdds['unknown'], guard.environment(plain_env()))
    assert report['state'] == 2 and report['active'] == 0, report
    assert report['wrong_returns'] == 0 and report['writes'] > 0, report
    assert report['calls'][0] == report['writes'], report  # interposed, and called through
    lines = [line for line in stderr.splitlines() if line.startswith(GUARD_LINE)]
    assert len(lines) == 1, stderr
    assert 'inactive' in lines[0] and 'libfastrtps.so.2.13' in lines[0], lines[0]
    assert 'not a Fast DDS version this guard knows' in lines[0], lines[0]


def test_guard_loaded_after_fastdds_reports_inactive(fake_fastdds: dict[str, str]) -> None:
    report, stderr = drive_fake(fake_fastdds['known'], plain_env(), '--load-guard-late',
                                guard.library_path())
    assert report['state'] == 2 and report['active'] == 0, report
    assert 'loaded after Fast DDS' in report['reason'], report
    assert report['wrong_returns'] == 0, report


def test_guard_with_fastdds_linked_into_the_executable(fake_fastdds: dict[str, str]) -> None:
    # A DT_NEEDED Fast DDS is mapped after LD_PRELOAD: that is the normal, active case.
    # Its own directory first, so that the loader does not pick the real libfastrtps.so.2.14.
    env = guard.environment(plain_env(LD_LIBRARY_PATH=str(Path(fake_fastdds['known']).parent)))
    result = run([fake_fastdds['linked_main']], env)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ['42', '1'], result.stdout + result.stderr


# --- the real stack -------------------------------------------------------------------------------

def scenario_env(guarded: bool, name: str) -> dict[str, str]:
    env = plain_env(GUARD_TOPIC=f'guard_chatter_{name}')
    return guard.environment(env) if guarded else env


def test_rclpy_publisher_runs_normally_under_the_guard(procs: list[Proc]) -> None:
    name = uuid.uuid4().hex[:8]
    listener = start(procs, 'listener', python_module(SCENARIO, 'listener', 10, 20),
                     scenario_env(False, name))
    assert listener.wait_for('READY', 30.0), listener.tail()
    talker = start(procs, 'talker', python_module(SCENARIO, 'talker', 40),
                   scenario_env(True, name))
    # Its exit is not asserted: one CI run saw this talker hang in rclpy shutdown after reporting
    # (rc None after 40 s); that is recorded as an open question, not hidden by a retry.
    assert talker.wait_for('CALLS', 40.0), talker.tail()
    status = talker.last('STATUS')
    assert status is not None and status.startswith(KNOWN_ACTIVE), talker.tail()
    calls = dict(kv.split('=') for kv in (talker.last('CALLS') or 'CALLS').split()[1:])
    assert int(calls.get('perform_create_new_change', 0)) >= 40, talker.tail()
    assert not any(line.startswith(GUARD_LINE) for line in talker.lines), talker.tail()
    received = listener.wait_for('RECEIVED', 30.0)
    assert received is not None and int(received.split()[1]) >= 10, listener.tail()


CHURN_UPDATES = 200
CHURN_INTERVAL = 0.02
FEEDBACK_PERIOD = 0.0005


def hazard_cell(event: str, guarded: bool, bound: int, settle: float = 0.5) -> dict:
    """A cell of :mod:`harness.hazard` (Fast-DDS issue 4878's events) at a 0.5 ms feedback period.

    A server (guarded or not) publishing feedback every 0.5 ms to a goal that an ordinary client
    keeps running, and a client of ``event`` up to ``bound`` times: ``update`` changes its
    feedback filter every 20 ms, ``destroy`` creates, matches and destroys a filtered client
    (``settle`` seconds for discovery each); its class as ``CFT_ACTION_WRITER_FILTERING`` says: the
    library's, or DDS-SQL. Returns what happened; the tests assert on it. The update cell with
    DDS-SQL on an unguarded server is a measurement, not a test: ``CFT_ACTION_WRITER_FILTERING=any
    python -m benchmarks.hazard --events update --guard off`` (docs/SAFETY.md).
    """
    cell = hazard.Cell(event, FEEDBACK_PERIOD, 'small', guarded, bound)
    opts = argparse.Namespace(interval=CHURN_INTERVAL, settle=settle, k=1, keep_cores=False)
    return hazard.run_cell(cell, opts, domain=int(os.environ['ROS_DOMAIN_ID']))


def test_churn_server_survives_with_the_guard() -> None:
    outcome = hazard_cell('update', guarded=True, bound=CHURN_UPDATES)
    dump = json.dumps(outcome, indent=1)
    assert 'error' not in outcome, dump
    assert ('STATUS True ' + (outcome['guard_status'] or '')).startswith(KNOWN_ACTIVE), dump
    assert outcome['survived'] and outcome['events'] == CHURN_UPDATES, dump
    assert outcome['server'] == 'alive' and 'server_at_stop' not in outcome, dump
    # The writer really went through the guard for both paths.
    calls = outcome['guard_calls']
    assert calls['perform_create_new_change'] > 1000, dump
    assert calls['process_reader_filter_info'] > 0, dump
    assert outcome['guard_messages'] == [], dump


def test_churn_of_the_library_filter_class_never_crashes_an_unguarded_server() -> None:
    """The default filter class is unknown to an unguarded server: it keeps no filter for the
    reader, so 200 filter changes at a 0.5 ms feedback period are nothing to it."""
    outcome = hazard_cell('update', guarded=False, bound=CHURN_UPDATES)
    dump = json.dumps(outcome, indent=1)
    assert 'error' not in outcome, dump
    assert outcome['survived'] and outcome['events'] == CHURN_UPDATES, dump
    assert outcome['server'] == 'alive' and 'server_at_stop' not in outcome, dump
