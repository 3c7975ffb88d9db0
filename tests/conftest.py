"""Session set-up: an isolated ROS domain, localhost-only discovery, and process hygiene."""

import os
import signal

from harness.domain import unused_domain  # no ROS import: the domain must come first

# Set before rclpy creates any context, and inherited by every process the tests start: a domain
# that no other process on this host uses, unless one is given.
os.environ['ROS_DOMAIN_ID'] = os.environ.get('CFT_TEST_DOMAIN_ID') or str(unused_domain())
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('CFT_ACTION_FEEDBACK_FILTER', None)

# A suite started as a background job without job control inherits SIGINT ignored, and exec keeps
# an ignored signal ignored in every process the tests start: the CLIs would then never see the
# Ctrl-C that tests send them (measured: `(make test &)` failed both CLI tests that way). A handled
# signal is reset to its default on exec, so handling it here gives every child its default back.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

import pytest

from harness.ros import RosSession


@pytest.fixture
def ros():
    """An rclpy context, one node and an executor, all shut down after the test."""
    session = RosSession()
    try:
        yield session
    finally:
        session.close()


def pytest_report_header(config):
    """The session's domain, so that a failure can be matched with the other processes on it."""
    return f"ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']} (LOCALHOST discovery)"
