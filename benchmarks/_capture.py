"""Where a client's received bytes go: a packet capture on the client's own interface.

Run inside a client's network namespace (needs root, as the namespaces do):
``python -m benchmarks._capture INTERFACE FEEDBACK_GUIDS STATUS_GUIDS`` (GUIDs in hex,
comma-separated). It prints
``SNIFFING`` once it listens, and on the line ``stop`` prints ``RESULT <json>``: received bytes
and packets (whole Ethernet frames, as ``rx_bytes`` counts them) by category:

- ``feedback data``: packets with a DATA submessage of the action's feedback writer;
- ``feedback gap/heartbeat``: other packets from that writer (GAPs for samples the writer
  filtered out, heartbeats) — the cost of writer-side filtering that is not data;
- ``status``: the status writer (every goal's status, to every client);
- ``discovery``: builtin RTPS endpoints (participant and endpoint discovery, liveliness);
- ``other``: everything else (service responses, acknowledgements of the client's own writers,
  ARP and IPv6 neighbour discovery).

IP fragments after the first are counted in the category of their first fragment.

``sweep.py --anatomy`` runs it on the first client of every phase, in a run of its own: capturing
costs CPU on the machine being measured.
"""

from __future__ import annotations

import json
import socket
import struct
import sys
import threading
from collections import Counter
from typing import Any

CATEGORIES = ('feedback data', 'feedback gap/heartbeat', 'status', 'discovery', 'other')

_DATA, _DATA_FRAG = 0x15, 0x16
# HEARTBEAT, GAP, HEARTBEAT_FRAG, ACKNACK and NACK_FRAG carry readerId, then writerId.
_WRITER_AFTER_READER = (0x07, 0x08, 0x13, 0x06, 0x12)


def _writer_ids(payload: bytes) -> list[tuple[int, bytes]]:
    """(submessage id, writer entity id) of each RTPS submessage that names a writer."""
    found = []
    offset = 20  # RTPS header: 'RTPS', version, vendor, GUID prefix
    while offset + 4 <= len(payload):
        kind, flags = payload[offset], payload[offset + 1]
        length = struct.unpack('<H' if flags & 1 else '>H', payload[offset + 2:offset + 4])[0]
        body = payload[offset + 4:offset + 4 + length] if length else payload[offset + 4:]
        if kind in (_DATA, _DATA_FRAG):
            found.append((kind, body[8:12]))  # extraFlags, octetsToInlineQos, readerId, writerId
        elif kind in _WRITER_AFTER_READER:
            found.append((kind, body[4:8]))
        if length == 0:  # the last submessage extends to the end of the datagram
            break
        offset += 4 + length
    return found


def classify(payload: bytes, feedback: set[bytes], status: set[bytes]) -> str:
    """The category of one RTPS datagram (``payload`` from the UDP payload on)."""
    if payload[:4] != b'RTPS':
        return 'other'
    prefix = payload[8:20]
    submessages = _writer_ids(payload)
    writers = {prefix + entity for _, entity in submessages}
    if any(kind in (_DATA, _DATA_FRAG) and prefix + entity in feedback
           for kind, entity in submessages):
        return 'feedback data'
    if writers & feedback:
        return 'feedback gap/heartbeat'
    if writers & status:
        return 'status'
    # Builtin endpoints have entity kinds with the two top bits set.
    if any(entity[3] & 0xc0 == 0xc0 for _, entity in submessages):
        return 'discovery'
    return 'other'


def capture(interface: str, feedback: set[bytes], status: set[bytes],
            stop: threading.Event) -> dict[str, dict[str, int]]:
    """Count received frames on ``interface`` by category until ``stop`` is set."""
    sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(3))  # ETH_P_ALL
    sock.bind((interface, 0))
    sock.settimeout(0.2)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 * 1024 * 1024)
    frames: Counter[str] = Counter()
    octets: Counter[str] = Counter()
    first_fragment: dict[tuple[bytes, int], str] = {}
    print('SNIFFING', flush=True)
    while not stop.is_set():
        try:
            frame, address = sock.recvfrom(65535)
        except socket.timeout:
            continue
        if address[2] == socket.PACKET_OUTGOING:
            continue
        category = 'other'
        if frame[12:14] == b'\x08\x00' and frame[23] == 17:  # IPv4, UDP
            header = (frame[14] & 0x0f) * 4
            ident, fragment = struct.unpack('!HH', frame[18:22])
            key = (frame[26:30], ident)
            if fragment & 0x1fff:
                category = first_fragment.get(key, 'other')
            else:
                category = classify(frame[14 + header + 8:], feedback, status)
                if fragment & 0x2000:  # more fragments follow
                    first_fragment[key] = category
        frames[category] += 1
        octets[category] += len(frame)
    return {c: {'bytes': octets[c], 'packets': frames[c]} for c in CATEGORIES}


def main() -> None:
    """Capture until ``stop`` on stdin, then print the counts."""
    interface = sys.argv[1]
    feedback = {bytes.fromhex(g) for g in sys.argv[2].split(',') if g}
    status = {bytes.fromhex(g) for g in sys.argv[3].split(',') if g}
    stop = threading.Event()
    result: dict[str, Any] = {}
    worker = threading.Thread(target=lambda: result.update(capture(interface, feedback, status,
                                                                   stop)))
    worker.start()
    for line in sys.stdin:
        if line.strip() == 'stop':
            break
    stop.set()
    worker.join(timeout=10)
    print('RESULT ' + json.dumps(result), flush=True)


if __name__ == '__main__':
    main()
