"""Session set-up: an isolated ROS domain, localhost-only discovery, and process hygiene."""

import os
import random
import signal

# Set before rclpy creates any context, and inherited by every process the tests start.
os.environ['ROS_DOMAIN_ID'] = os.environ.get('CFT_TEST_DOMAIN_ID') or str(random.randint(1, 101))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('CFT_ACTION_FEEDBACK_FILTER', None)

# A suite started as a background job without job control inherits SIGINT ignored, and exec keeps
# an ignored signal ignored in every process the tests start: the CLIs would then never see the
# Ctrl-C that tests send them (measured: `(make test &)` failed both CLI tests that way). A handled
# signal is reset to its default on exec, so handling it here gives every child its default back.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

import pytest  # noqa: E402

from harness.ros import RosSession  # noqa: E402


@pytest.fixture
def ros():
    """An rclpy context, one node and an executor, all shut down after the test."""
    session = RosSession()
    try:
        yield session
    finally:
        session.close()
