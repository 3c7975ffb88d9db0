"""The README's install path for users of apt's ROS 2 Jazzy, run with this machine's externally
managed ``python3`` (PEP 668): a venv with ``--system-site-packages`` beside a sourced ROS.

What it checks is the system's Python (``/usr/bin/python3``), whatever Python runs pytest. Where
that is one of the Pythons the suite runs on (:data:`SUITE_PYTHONS`, as ``.ci/run`` does), the
suite of that Python runs it (3.11 on Debian 12, Noble's 3.12 on Ubuntu 24.04), and the other
suite skips it: it would repeat the same check after downloading the wheels again.

There is no apt ROS here. ``tests.helpers.ros_prefix`` lays out a prefix shaped like
``/opt/ros/jazzy`` from the ROS wheels, and a ``setup.bash`` that exports what apt's does for
Python (``AMENT_PREFIX_PATH``, ``PYTHONPATH``, ``LD_LIBRARY_PATH``). The wheels come from this
test's venv when its Python is the system's version, and otherwise (a system Python that no
suite runs on) from a venv of the system Python into which this test installs them from PyPI
(measured: 12 s). Apt's ROS takes NumPy, PyYAML and
lark from the system's Python; here they are in the prefix, beside rclpy: the test shows where
``rclpy`` and ``cft_action`` come from, not where rclpy's own requirements do.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from packaging.requirements import Requirement

from tests.support import ROOT, copy_package
from tests.test_readme import readme_example

SYSTEM_PYTHON = Path('/usr/bin/python3')
# measured on a 2-core machine: the install 7 s (its build downloads setuptools and ros-fastrtps
# for pip's isolated build environment), the venv 3 s
INSTALL_TIMEOUT = 300
#: The Pythons of ROS 2 Jazzy's wheels, on each of which .ci/run runs the suite.
SUITE_PYTHONS = ((3, 11), (3, 12))

# Run in the venv after the README's commands: where each module comes from, and that the
# library works there (its reader library loads and filters a real client's feedback).
CHECK = """
import ctypes, importlib.metadata, json, os, sys, sysconfig
import rclpy
from test_msgs.action import Fibonacci
import cft_action
from cft_action import ActionClient, guard
rclpy.init()
node = rclpy.create_node('cft_apt_install')
client = ActionClient(node, Fibonacci, 'cft_apt_install')
state = client.feedback_filter_state
client.destroy()
node.destroy_node()
rclpy.shutdown()
venv = [d.metadata['Name']
        for d in importlib.metadata.distributions(path=[sysconfig.get_path('purelib')])]
library = ctypes.CDLL(guard.library_path(), mode=os.RTLD_LOCAL)
library.cft_guard_layout_includes.restype = ctypes.c_char_p
print(json.dumps({'prefix': sys.prefix, 'rclpy': rclpy.__file__,
                  'cft_action': cft_action.__file__, 'filter_active': state.active,
                  'filter_reason': state.reason, 'venv_distributions': venv,
                  'layout_includes': library.cft_guard_layout_includes().decode()}))
"""


def system_python_version() -> tuple[int, int]:
    if not SYSTEM_PYTHON.exists():
        pytest.skip(f'{SYSTEM_PYTHON} does not exist: this machine has no system Python')
    version = subprocess.run(
        [str(SYSTEM_PYTHON), '-c', 'import sys; print(*sys.version_info[:2])'],
        capture_output=True, text=True, check=True, timeout=30).stdout.split()
    return int(version[0]), int(version[1])


def shell_env() -> dict[str, str]:
    """A user's shell before sourcing ROS: without this venv's ROS libraries, the repository
    or any environment of this test run."""
    env = {k: v for k, v in os.environ.items()
           if k not in ('PYTHONPATH', 'LD_LIBRARY_PATH', 'AMENT_PREFIX_PATH', 'VIRTUAL_ENV',
                        '_ROS_WHEELS_BOOTSTRAP_COMPLETE', 'PYTHONHOME')}
    env['PATH'] = os.pathsep.join(p for p in env.get('PATH', '').split(os.pathsep)
                                  if p and Path(p).resolve() != Path(sys.prefix, 'bin').resolve())
    return env


def ros_wheels_python(version: tuple[int, int], tmp_path: Path, env: dict[str, str]) -> str:
    """A Python of the system's version that has the ROS wheels of the ``[jazzy]`` extra."""
    if sys.version_info[:2] == version:
        return sys.executable
    wheels = tmp_path / 'ros-wheels'
    subprocess.run([str(SYSTEM_PYTHON), '-m', 'venv', str(wheels)], check=True, env=env,
                   timeout=120)
    jazzy = [Requirement(r) for r in importlib.metadata.requires('cft-action') or []
             if 'extra == "jazzy"' in r]
    specifiers = [f'{r.name}[{",".join(sorted(r.extras))}]{r.specifier}' if r.extras
                  else f'{r.name}{r.specifier}' for r in jazzy]
    install = subprocess.run(
        [str(wheels / 'bin' / 'pip'), 'install', '--quiet', *specifiers, 'packaging'],
        capture_output=True, text=True, env=env, timeout=INSTALL_TIMEOUT)
    assert install.returncode == 0, install.stdout + install.stderr
    return str(wheels / 'bin' / 'python')


def test_readme_install_beside_apt_ros_with_an_externally_managed_python(tmp_path):
    version = system_python_version()
    if version != sys.version_info[:2] and version in SUITE_PYTHONS:
        pytest.skip(f'checks the system Python {version[0]}.{version[1]}, whatever Python runs '
                    f'pytest: the suite on Python {version[0]}.{version[1]} runs it')
    marker = Path(f'/usr/lib/python{version[0]}.{version[1]}/EXTERNALLY-MANAGED')
    assert marker.is_file(), f'{SYSTEM_PYTHON} is not externally managed (no {marker})'
    env = shell_env()
    package = tmp_path / 'cft_action'
    copy_package(package)

    # What the README said before: pip refuses the system's Python.
    refused = subprocess.run([str(SYSTEM_PYTHON), '-m', 'pip', 'install', '--dry-run',
                              '--no-index', str(package)],
                             capture_output=True, text=True, env=env, timeout=60)
    assert refused.returncode != 0 and 'externally-managed-environment' in refused.stderr, \
        refused.stdout + refused.stderr

    ros = tmp_path / 'opt_ros_jazzy'
    layout = subprocess.run(
        [ros_wheels_python(version, tmp_path, env), '-m', 'tests.helpers.ros_prefix', str(ros)],
        capture_output=True, text=True, cwd=ROOT, env=env, timeout=60)
    assert layout.returncode == 0, layout.stdout + layout.stderr
    site = layout.stdout.strip()

    # The README's commands, with this machine's paths; then the check, in the activated venv.
    commands = readme_example('apt_install', 'bash')
    venv = tmp_path / 'cft-venv'
    for old, new in (('/opt/ros/jazzy/setup.bash', str(ros / 'setup.bash')),
                     ('python3 -m venv', f'{SYSTEM_PYTHON} -m venv'),
                     ('~/cft-venv', str(venv)), ('install cft-action', f'install {package}')):
        assert old in commands, f'the README example apt_install has no {old!r}: {commands}'
        commands = commands.replace(old, new)
    commands = '\n'.join(line.split('#')[0] for line in commands.splitlines())
    script = f'set -e\n{commands}\npython3 - <<"EOF"\n{CHECK}EOF\n'
    run = subprocess.run(['bash', '-c', script], capture_output=True, text=True, cwd=tmp_path,
                         env=env, timeout=INSTALL_TIMEOUT)
    log = run.stdout + run.stderr
    assert run.returncode == 0, log
    found = json.loads(run.stdout.strip().splitlines()[-1])

    assert found['prefix'] == str(venv), log
    assert found['rclpy'].startswith(site + os.sep), log  # from the sourced ROS
    assert found['cft_action'].startswith(str(venv) + os.sep), log  # from the venv
    assert found['filter_active'], found['filter_reason']
    # pip installed the library only: no ROS package, and PyYAML was there already.
    installed = {name.lower() for name in found['venv_distributions']}
    assert 'cft-action' in installed, log
    assert not [n for n in installed if re.match(r'ros[-_]|numpy|pyyaml', n)], installed
    assert 'include-system-site-packages = true' in (venv / 'pyvenv.cfg').read_text()
    # The build compiled against the sourced ROS's Fast DDS headers, not the build requirement's.
    assert found['layout_includes'].split(os.pathsep)[0] == str(ros / 'include'), log
