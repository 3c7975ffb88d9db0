"""A throttle relay node, as topic_tools' ``throttle messages IN HZ OUT``: the anchor that
:mod:`benchmarks.rate` compares rate-limited subscriptions with.

It subscribes to every message of a topic (a plain subscription: every message crosses the network
to it) and republishes one on ``OUT`` when at least ``1/HZ`` seconds have passed since the last one
it republished, as topic_tools' throttle does in its ``messages`` mode.
"""

from __future__ import annotations

import time
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile


class ThrottleRelay:
    """Republish ``topic_in`` on ``topic_out`` at most ``hz`` times a second."""

    def __init__(self, node: Node, msg_type: Any, topic_in: str, topic_out: str, hz: float,
                 qos: QoSProfile) -> None:
        """Create the relay's publisher and its plain subscription on ``node``."""
        self.period = 1.0 / hz
        self.received = 0
        self.republished = 0
        self._last = -float('inf')
        self.publisher = node.create_publisher(msg_type, topic_out, qos)
        self.subscription = node.create_subscription(msg_type, topic_in, self._relay, qos)

    def _relay(self, message: Any) -> None:
        self.received += 1
        now = time.monotonic()
        if now - self._last >= self.period:
            self._last = now
            self.publisher.publish(message)
            self.republished += 1
