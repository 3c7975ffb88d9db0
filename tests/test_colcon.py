"""The install path for users of an existing ROS (apt's ROS 2 Jazzy, or their own workspaces):
`pip install cft-action` brings no ROS wheel, and `colcon build` builds the package in a
workspace on top of that ROS.

There is no apt ROS here: this venv, with the ROS wheels, is the underlay. colcon (from PyPI, the
test extra) builds with the Python it runs on, so the venv's ``bin`` first on ``PATH`` is all it
needs. The build compiles the two C shared libraries (setup.py's extensions); then the install
space alone must give ``cft-action`` on ``PATH`` and the package that the README's tutorial
client imports, against a server under the install space's guard.
"""

from __future__ import annotations

import importlib.metadata
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.support import copy_package
from tests.test_readme import check_tutorial_log, run_tutorial_client

ROOT = Path(__file__).resolve().parent.parent
BUILD_TIMEOUT = 180  # measured: about 10 s on this 2-core machine


def _clean_env() -> dict[str, str]:
    """This process's environment without the repository on PYTHONPATH, the venv's bin first on
    PATH: what a user's shell with a sourced ROS looks like here."""
    env = dict(os.environ)
    paths = [p for p in env.get('PYTHONPATH', '').split(os.pathsep)
             if p and Path(p).resolve() != ROOT]
    env['PYTHONPATH'] = os.pathsep.join(paths)
    env['PATH'] = os.pathsep.join([str(Path(sys.executable).parent), env.get('PATH', '')])
    return env


def _sourced(workspace: Path, command: str, env: dict[str, str]) -> subprocess.CompletedProcess:
    """``command`` in bash after ``source install/setup.bash``."""
    return subprocess.run(
        ['bash', '-c', f'source {workspace}/install/setup.bash && {command}'], env=env,
        cwd=workspace, capture_output=True, text=True, timeout=60)


def test_pip_installs_no_ros_wheel_without_the_jazzy_or_kilted_extra():
    """`pip install cft-action` next to an existing ROS must not bring a second ROS from PyPI."""
    requirements = importlib.metadata.requires('cft-action') or []
    always = [r for r in requirements if 'extra ==' not in r]
    assert always == ['pyyaml>=6'], always
    ros = [r for r in requirements if r.startswith('ros-')]
    for distro in ('jazzy', 'kilted'):
        of_distro = [r for r in ros if r.endswith(f'extra == "{distro}"')]
        assert len(of_distro) == 3 and all(r.startswith(f'ros-{distro}-') for r in of_distro), ros
    assert len(ros) == 6, ros


@pytest.fixture(scope='module')
def workspace(tmp_path_factory) -> Path:
    if shutil.which('colcon', path=str(Path(sys.executable).parent)) is None:
        pytest.fail('colcon is not installed in this venv: `make test` installs the test extra')
    workspace = tmp_path_factory.mktemp('colcon_ws')
    copy_package(workspace / 'src' / 'cft_action')
    start = time.monotonic()
    build = subprocess.run(
        [str(Path(sys.executable).parent / 'colcon'), 'build', '--event-handlers',
         'console_direct+'], cwd=workspace, env=_clean_env(), capture_output=True, text=True,
        timeout=BUILD_TIMEOUT)
    seconds = time.monotonic() - start
    log = build.stdout[-6000:] + build.stderr[-6000:]
    assert build.returncode == 0, log
    assert 'Summary: 1 package finished' in build.stdout, log
    # colcon-ros's fallbacks, which it says will go away: the package installs both itself
    assert "doesn't explicitly install" not in log, log
    print(f'colcon build took {seconds:.1f} s')
    return workspace


def test_colcon_build_installs_the_command_and_both_libraries(workspace):
    env = _clean_env()
    found = _sourced(workspace, 'command -v cft-action', env)
    assert found.returncode == 0, found.stderr
    assert found.stdout.strip() == str(workspace / 'install' / 'cft_action' / 'bin' / 'cft-action')
    usage = _sourced(workspace, 'cft-action --help', env)
    assert usage.returncode == 0, usage.stderr
    assert usage.stdout.startswith('usage: cft-action [-h] <command> ...'), usage.stdout
    echo = _sourced(workspace, 'cft-action topic echo --help', env)
    assert '--content-filter EXPR' in echo.stdout, echo.stdout + echo.stderr
    libraries = sorted(p.name.split('.')[0] for p in
                       (workspace / 'install' / 'cft_action').rglob('cft_action/_cft*.so'))
    assert libraries == ['_cftguard', '_cftreader']
    share = workspace / 'install' / 'cft_action' / 'share'
    assert (share / 'cft_action' / 'package.xml').is_file()
    assert (share / 'ament_index' / 'resource_index' / 'packages' / 'cft_action').is_file()


def test_readme_tutorial_client_from_the_install_space(workspace, tmp_path):
    sourced = _sourced(workspace, 'env -0', _clean_env())
    assert sourced.returncode == 0, sourced.stderr
    env = dict(line.split('=', 1) for line in sourced.stdout.split('\0') if '=' in line)
    install = workspace / 'install'
    where = subprocess.run(
        [sys.executable, '-c', 'import cft_action, cft_action.guard as g; '
                               'print(cft_action.__file__); print(g.library_path())'],
        env=env, cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert where.returncode == 0, where.stderr
    package, library = where.stdout.split()
    assert Path(package).is_relative_to(install), package  # not the repository's, nor the venv's
    assert Path(library).is_relative_to(install), library
    preload = _sourced(workspace, 'cft-action guard --print-path', env)
    assert preload.stdout.strip() == library, preload.stderr
    server_env = {**os.environ, 'LD_PRELOAD': library}
    check_tutorial_log(run_tutorial_client(tmp_path, client_env=env, server_env=server_env))
