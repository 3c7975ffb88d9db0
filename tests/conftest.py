"""Session set-up: an isolated ROS domain, localhost-only discovery, and process hygiene."""

import os
import random

# Set before rclpy creates any context, and inherited by every process the tests start.
os.environ['ROS_DOMAIN_ID'] = os.environ.get('CFT_TEST_DOMAIN_ID') or str(random.randint(1, 101))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('CFT_ACTION_FEEDBACK_FILTER', None)

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
