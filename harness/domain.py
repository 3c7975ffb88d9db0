"""A ROS domain that no other process on this host is using, for a test session or a benchmark.

Processes on one domain discover each other, and with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``
every process of this host on that domain does: a test whose server must discover its client
then also discovers, and waits on, whatever else runs there (another session's soak, a benchmark
left running). A random pick among 1..101 collides with a busy domain now and then; this one skips
the domains in which a participant has bound a port.
"""

from __future__ import annotations

import importlib.metadata
import random
from pathlib import Path
from typing import Optional

#: The domains whose ports stay below Linux's ephemeral range (ROS 2's "domain ID" guide).
DOMAINS = range(1, 102)

#: RTPS port mapping (RTPS 9.6.1.1, Fast DDS's defaults): a domain's ports are PB + DG * domain +
#: offsets below DG, for every participant of it.
PORT_BASE, DOMAIN_GAIN = 7400, 250


def domain_of_port(port: int) -> Optional[int]:
    """The domain whose RTPS port range holds ``port``, or None."""
    if port < PORT_BASE:
        return None
    return (port - PORT_BASE) // DOMAIN_GAIN


def busy_domains() -> set[int]:
    """The domains in which some process of this network namespace has bound a UDP port."""
    busy: set[int] = set()
    for table in ('/proc/net/udp', '/proc/net/udp6'):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) > 1 and ':' in fields[1]:
                domain = domain_of_port(int(fields[1].rsplit(':', 1)[1], 16))
                if domain is not None:
                    busy.add(domain)
    return busy


def unused_domain(rng: Optional[random.Random] = None) -> int:
    """A random domain of :data:`DOMAINS` that no process here uses; any of them if all are used."""
    rng = rng or random.Random()
    busy = busy_domains()
    free = [domain for domain in DOMAINS if domain not in busy]
    return rng.choice(free or list(DOMAINS))


def profiles_variable() -> str:
    """The variable through which the installed rmw_fastrtps reads a Fast DDS profile file: Fast
    DDS 2's for rmw_fastrtps 8 (Jazzy), which reads no other; Fast DDS 3's for rmw_fastrtps 9+,
    which warns in every process that the other is deprecated."""
    try:
        major = int(importlib.metadata.version('ros-rmw-fastrtps-shared-cpp').split('.')[0])
    except (importlib.metadata.PackageNotFoundError, ValueError):
        major = 8
    return 'FASTDDS_DEFAULT_PROFILES_FILE' if major >= 9 else 'FASTRTPS_DEFAULT_PROFILES_FILE'
