"""Session set-up: an isolated ROS domain, localhost-only discovery, and process hygiene."""

import ctypes
import os
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

from harness.domain import profiles_variable, unused_domain  # no ROS import: they come first

# Set before rclpy creates any context, and inherited by every process the tests start: a domain
# that no other process on this host uses, unless one is given.
os.environ['ROS_DOMAIN_ID'] = os.environ.get('CFT_TEST_DOMAIN_ID') or str(unused_domain())
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('CFT_ACTION_FEEDBACK_FILTER', None)

# Every participant of the suite announces itself every 0.5 s instead of every 3 s
# (tests/discovery_profile.xml). Processes started together often learn of a running server only
# at its next announcement: three client processes started at once waited 1.75-3.0 s in
# wait_for_server, plain rclpy and this library alike, where one alone waited 0.25 s; at 0.5 s
# they waited 0.01-0.5 s, and the suite took 530 s instead of 590. No test checks how soon
# participants meet; endpoint discovery and every writer's heartbeats keep their defaults. A
# profile file given in the environment is kept.
if not {'FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE'} & set(os.environ):
    os.environ[profiles_variable()] = str(Path(__file__).with_name('discovery_profile.xml'))

# A suite started as a background job without job control inherits SIGINT ignored, and exec keeps
# an ignored signal ignored in every process the tests start: the CLIs would then never see the
# Ctrl-C that tests send them (measured: `(make test &)` failed both CLI tests that way). A handled
# signal is reset to its default on exec, so handling it here gives every child its default back.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

import pytest

from harness.ros import RosSession, unique_name
from tests.support import helper_process


@pytest.fixture
def ros():
    """An rclpy context, one node and an executor, all shut down after the test."""
    session = RosSession()
    try:
        yield session
    finally:
        session.close()


def pytest_configure(config):
    """A native backtrace of this process if it dies of a signal (tests/helpers/native_backtrace.c).

    Written to a copy of the stderr the suite started with, as faulthandler writes its Python
    frames: output capture replaces descriptor 2 during each test.
    """
    config.native_backtrace = install_native_backtrace()


def install_native_backtrace() -> str:
    """Compile and install the handler; say what came of it (for the report header)."""
    compiler, gdb, timeout = shutil.which('cc') or shutil.which('gcc'), shutil.which('gdb'), \
        shutil.which('timeout')
    if not (compiler and gdb and timeout):
        return 'off (needs cc, gdb and timeout on PATH)'
    source = Path(__file__).parent / 'helpers' / 'native_backtrace.c'
    library = Path(tempfile.mkdtemp(prefix='cft-native-backtrace-')) / 'native_backtrace.so'
    built = subprocess.run([compiler, '-shared', '-fPIC', '-O1', '-o', str(library), str(source)],
                           capture_output=True, text=True, timeout=60)
    if built.returncode != 0:
        return f'off (does not compile: {built.stderr.strip()[:200]})'
    install = ctypes.CDLL(str(library)).native_backtrace_install
    shutil.rmtree(library.parent)  # loaded: the mapping outlives the file
    install.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_int]
    if install(timeout.encode(), gdb.encode(), 120, os.dup(2)) != 0:
        return 'off (sigaction failed)'
    return f'on ({gdb})'


def pytest_report_header(config):
    """The session's domain, so that a failure can be matched with the other processes on it."""
    return [f"ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']} (LOCALHOST discovery)",
            f'native backtrace on a fatal signal: {config.native_backtrace}']


@pytest.fixture
def publisher():
    """tests/helpers/publisher.py in its own process: yields (its topics' prefix, the process)."""
    prefix = '/' + unique_name('cft_pub')
    child = helper_process('tests.helpers.publisher', [prefix])
    try:
        yield prefix, child
    finally:
        child.stop()
