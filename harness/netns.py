"""One network namespace per process, so that each client's received bytes can be counted.

The topology: the server's namespace holds a bridge ``br0`` (10.213.0.1/16); each client has its
own namespace with one veth interface ``cft0``, whose peer is an isolated port of that bridge, so a
client reaches the server and no other client: a star. Nothing is connected to the host's network,
so discovery multicast stays inside, and the ``cft0`` counters of a client count exactly what the
server sent to it: feedback, status, service responses and discovery, with their UDP, IP and
Ethernet headers. (On a flat LAN the clients would also discover each other, which adds the same
bytes to every configuration.)

Fast DDS must use UDP for this (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``): its shared-memory transport
works across network namespaces, since they share ``/dev/shm``, and would bypass the counters.

Needs root and ``ip`` from iproute2; :func:`unavailable_reason` says why not, for the fallback.
Namespace names start with ``cftb<pid>``, so a run can remove what a crashed run of its own left.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from typing import Optional, Sequence

PREFIX = 'cftb'
SERVER_ADDRESS = '10.213.0.1'
INTERFACE = 'cft0'

#: Environment for every process in a namespace: UDP only, and discovery on the (private) subnet.
ENVIRONMENT = {'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}


def _ip(*args: str) -> None:
    subprocess.run(['ip', *args], check=True, capture_output=True, text=True, timeout=20)


def unavailable_reason() -> Optional[str]:
    """None when namespaces can be made here, else why not."""
    if os.geteuid() != 0:
        return 'not root'
    if shutil.which('ip') is None:
        return 'no ip command (iproute2)'
    probe = f'{PREFIX}{os.getpid()}probe'
    try:
        _ip('netns', 'add', probe)
        _ip('netns', 'del', probe)
    except (subprocess.CalledProcessError, subprocess.TimeoutExpired, OSError) as e:
        detail = getattr(e, 'stderr', '') or str(e)
        return f'ip netns add failed: {detail.strip()}'
    return None


def remove_stale() -> None:
    """Delete namespaces left by runs of this module whose process is gone."""
    try:
        listing = subprocess.run(['ip', 'netns', 'list'], capture_output=True, text=True,
                                 timeout=20).stdout
    except (OSError, subprocess.TimeoutExpired):
        return
    for line in listing.splitlines():
        match = re.match(rf'({PREFIX}(\d+)\S*)', line)
        if match and not os.path.exists(f'/proc/{match.group(2)}'):
            subprocess.run(['ip', 'netns', 'del', match.group(1)], capture_output=True, timeout=20)


class Topology:
    """The server's namespace with its bridge, and one namespace per client, joined by veths."""

    def __init__(self) -> None:
        """Create the server's namespace and bridge."""
        self.tag = f'{PREFIX}{os.getpid()}r{os.urandom(2).hex()}'
        self.server = f'{self.tag}s'
        self.namespaces: list[str] = []
        self.clients: list[str] = []
        self._clients = 0
        self._add_namespace(self.server)
        _ip('-n', self.server, 'link', 'add', 'br0', 'type', 'bridge', 'mcast_snooping', '0')
        _ip('-n', self.server, 'addr', 'add', f'{SERVER_ADDRESS}/16', 'dev', 'br0')
        _ip('-n', self.server, 'link', 'set', 'br0', 'up')
        _ip('-n', self.server, 'route', 'add', '224.0.0.0/4', 'dev', 'br0')

    def _add_namespace(self, name: str) -> None:
        _ip('netns', 'add', name)
        self.namespaces.append(name)
        _ip('-n', name, 'link', 'set', 'lo', 'up')

    def add_client(self, loss_percent: float = 0.0) -> str:
        """Create a client namespace joined to the bridge; return its name. ``loss_percent``: the
        share of the server's packets that the client's namespace drops as they arrive (an
        ``iptables`` ``statistic`` rule; this kernel has no ``netem``). They count in ``rx_bytes``:
        the server sent them."""
        index = self._clients
        self._clients += 1
        name = f'{self.tag}c{index}'
        self._add_namespace(name)
        port = f'p{index}'
        _ip('link', 'add', INTERFACE, 'netns', name, 'type', 'veth', 'peer', 'name', port,
            'netns', self.server)
        address = f'10.213.{1 + index // 250}.{1 + index % 250}/16'
        _ip('-n', name, 'addr', 'add', address, 'dev', INTERFACE)
        _ip('-n', name, 'link', 'set', INTERFACE, 'up')
        # Fast DDS sends discovery to 239.255.0.1; without a route for it the send fails.
        _ip('-n', name, 'route', 'add', '224.0.0.0/4', 'dev', INTERFACE)
        _ip('-n', self.server, 'link', 'set', port, 'master', 'br0', 'up')
        # Isolated ports reach the server (the bridge itself) but not each other: a star, as if
        # every client had its own link to the server. A full mesh of N participants would also
        # need N x N ARP entries, and Linux's ARP table (1024 entries by default, shared by all
        # namespaces) overflowed at 32 clients, silently cutting the last ones off.
        _ip('-n', self.server, 'link', 'set', 'dev', port, 'type', 'bridge_slave', 'isolated', 'on')
        if loss_percent > 0:
            if shutil.which('iptables') is None:
                raise RuntimeError('a loss needs iptables (apt-get install iptables)')
            subprocess.run(self.command(name, [
                'iptables', '-A', 'INPUT', '-s', SERVER_ADDRESS, '-m', 'statistic', '--mode',
                'random', '--probability', f'{loss_percent / 100:.4f}', '-j', 'DROP']),
                check=True, capture_output=True, text=True, timeout=20)
        self.clients.append(name)
        return name

    @staticmethod
    def command(namespace: str, argv: Sequence[str]) -> list[str]:
        """``argv`` run inside ``namespace`` (``ip netns exec`` execs it: the pid is the same)."""
        return ['ip', 'netns', 'exec', namespace, *argv]

    def close_clients(self) -> None:
        """Delete the client namespaces (their veths go with them). Stop their processes first."""
        for name in self.clients:
            subprocess.run(['ip', 'netns', 'del', name], capture_output=True, timeout=20)
            self.namespaces.remove(name)
        self.clients.clear()

    def close(self) -> None:
        """Delete every namespace. Stop their processes first."""
        for name in reversed(self.namespaces):
            subprocess.run(['ip', 'netns', 'del', name], capture_output=True, timeout=20)
        self.namespaces.clear()
        self.clients.clear()


def interface_counters(pid: int, interface: str = INTERFACE) -> Optional[dict[str, int]]:
    """``rx_bytes``, ``rx_packets``, ``tx_bytes``, ``tx_packets`` of ``interface`` in the network
    namespace of process ``pid``, or None if the process or the interface is gone."""
    try:
        with open(f'/proc/{pid}/net/dev') as dev:
            lines = dev.readlines()
    except OSError:
        return None
    for line in lines[2:]:
        name, _, values = line.partition(':')
        if name.strip() == interface:
            fields = [int(v) for v in values.split()]
            return {'rx_bytes': fields[0], 'rx_packets': fields[1],
                    'tx_bytes': fields[8], 'tx_packets': fields[9]}
    return None
