"""The session's domain: one that no other process on this host is using."""

import random
import socket

from harness.domain import DOMAIN_GAIN, DOMAINS, PORT_BASE, busy_domains, unused_domain


def test_a_domain_with_a_bound_port_is_never_chosen():
    busy = busy_domains()
    domain = random.Random().choice([d for d in DOMAINS if d not in busy])
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as participant:
        participant.bind(('127.0.0.1', PORT_BASE + DOMAIN_GAIN * domain + 11))  # a unicast port
        assert domain in busy_domains()
        assert all(unused_domain(random.Random(seed)) != domain for seed in range(100))
