"""Where a client's received bytes go: a packet capture on the client's own interface.

Run inside a client's network namespace (needs root, as the namespaces do):
``python -m harness.capture INTERFACE FEEDBACK_GUIDS STATUS_GUIDS`` (GUIDs in hex,
comma-separated). It prints
``SNIFFING`` once it listens, and on the line ``stop`` prints ``RESULT <json>``: received bytes
and packets (whole Ethernet frames, as ``rx_bytes`` counts them) by category, and ``samples``: the
DATA submessages (a fragmented sample once) of the feedback writers in ``feedback data`` and of the
status writers in ``status``, i.e. the samples the writer sent this client (0 in the others); and
for ``status`` also ``datagrams``, the UDP length of each datagram that starts a status sample
(whole, before IP fragmentation: the size of one status message on the wire):

- ``feedback data``: packets with a DATA submessage of the action's feedback writer;
- ``feedback gap/heartbeat``: other packets from that writer (GAPs for samples the writer
  filtered out, heartbeats) — the cost of writer-side filtering that is not data;
- ``status``: the status writer (every goal's status, to every client);
- ``discovery``: builtin RTPS endpoints (participant and endpoint discovery, liveliness);
- ``other``: everything else (service responses, acknowledgements of the client's own writers,
  ARP and IPv6 neighbour discovery).

IP fragments after the first are counted in the category of their first fragment.

``feedback data`` also has ``resent_bytes`` and ``resent_packets``: the frames of datagrams whose
feedback DATA carried only sequence numbers already received (repairs the writer sent again after
a NACK or a lost fragment).

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
from typing import Any, Iterator, NamedTuple, Optional

CATEGORIES = ('feedback data', 'feedback gap/heartbeat', 'status', 'discovery', 'other')

_DATA, _DATA_FRAG = 0x15, 0x16
_HEARTBEAT, _GAP = 0x07, 0x08
# HEARTBEAT, GAP, HEARTBEAT_FRAG, ACKNACK and NACK_FRAG carry readerId, then writerId.
_WRITER_AFTER_READER = (0x07, 0x08, 0x13, 0x06, 0x12)
# DDS Security's: a submessage protected alone (metadata protection) and a whole message (RTPS
# protection) begin so; under SIGN the protected submessages follow in clear, under ENCRYPT in a
# SEC_BODY.
_SEC_PREFIX, _SRTPS_PREFIX = 0x31, 0x33


def _submessages(payload: bytes) -> Iterator[tuple[int, int, bytes]]:
    """(submessage id, flags, body after its 4-byte header) of each submessage of one RTPS
    datagram, in order."""
    offset = 20  # RTPS header: 'RTPS', version, vendor, GUID prefix
    while offset + 4 <= len(payload):
        kind, flags = payload[offset], payload[offset + 1]
        length = struct.unpack('<H' if flags & 1 else '>H', payload[offset + 2:offset + 4])[0]
        end = offset + 4 + length if length else len(payload)
        yield kind, flags, payload[offset + 4:end]
        if length == 0:  # the last submessage extends to the end of the datagram
            break
        offset += 4 + length


def _writer_ids(payload: bytes) -> list[tuple[int, bytes, bool]]:
    """(submessage id, writer entity id, starts a sample) of each RTPS submessage that names a
    writer; a sample starts with a DATA, or with the DATA_FRAG of its first fragment."""
    found = []
    for kind, flags, body in _submessages(payload):
        if kind == _DATA:
            found.append((kind, body[8:12], True))  # extraFlags, octetsToInlineQos, readerId,
        elif kind == _DATA_FRAG:                    # writerId, then writerSN (8 bytes)
            first = struct.unpack('<I' if flags & 1 else '>I', body[20:24])[0] == 1
            found.append((kind, body[8:12], first))
        elif kind in _WRITER_AFTER_READER:
            found.append((kind, body[4:8], False))
    return found


_PID_SENTINEL, _PID_CONTENT_FILTER_INFO = 0x0001, 0x0055
#: Linux's SO_RCVBUFFORCE (asm-generic/socket.h), which Python's socket module does not name.
_SO_RCVBUFFORCE = 33


def _samples(payload: bytes) -> Iterator[tuple[int, int, str, bytes, bytes, int]]:
    """(submessage id, flags, byte order, body, writer GUID, sequence number) of each DATA and
    DATA_FRAG submessage of one RTPS datagram (the body after the submessage's 4-byte header)."""
    if payload[:4] != b'RTPS':
        return
    prefix = payload[8:20]
    for kind, flags, body in _submessages(payload):
        order = '<' if flags & 1 else '>'
        if kind in (_DATA, _DATA_FRAG) and len(body) >= 20:
            high, low = struct.unpack(order + 'iI', body[12:20])
            yield kind, flags, order, body, prefix + body[8:12], (high << 32) | low


def data_sequence_numbers(payload: bytes) -> list[tuple[bytes, int]]:
    """(writer GUID, sequence number) of each DATA submessage of one RTPS datagram."""
    return [(writer, sequence) for kind, _, _, _, writer, sequence in _samples(payload)
            if kind == _DATA]


def _inline_qos(body: bytes, order: str) -> Iterator[tuple[int, int, int]]:
    """(parameter id, offset of its value, its length) of each inline QoS parameter of one DATA or
    DATA_FRAG submessage body, up to and with the sentinel."""
    at = 4 + struct.unpack(order + 'H', body[2:4])[0]  # octetsToInlineQos counts from there
    while at + 4 <= len(body):
        pid, length = struct.unpack(order + 'HH', body[at:at + 4])
        yield pid, at + 4, length
        if pid == _PID_SENTINEL:
            return
        at += 4 + length


def _signatures(body: bytes, order: str) -> Optional[int]:
    """The number of filter signatures in the inline QoS of one DATA or DATA_FRAG submessage body,
    or None when it has no ``PID_CONTENT_FILTER_INFO``."""
    for pid, at, _ in _inline_qos(body, order):
        if pid & 0x3fff == _PID_CONTENT_FILTER_INFO:
            # filterResult: sequence<long> of bitmaps, then filterSignatures: sequence<long[4]>.
            bitmaps = struct.unpack(order + 'I', body[at:at + 4])[0]
            start = at + 4 + 4 * bitmaps
            return int(struct.unpack(order + 'I', body[start:start + 4])[0])
    return None


def filter_signatures(payload: bytes) -> list[tuple[bytes, int, Optional[int]]]:
    """(writer GUID, sequence number, signatures) of each DATA and DATA_FRAG submessage of one RTPS
    datagram: how many readers' filter signatures (``PID_CONTENT_FILTER_INFO``) its inline QoS
    carries, None without that parameter."""
    return [(writer, sequence, _signatures(body, order) if flags & 0x02 else None)  # Q: inline QoS
            for _, flags, order, body, writer, sequence in _samples(payload)]


def classify(payload: bytes, feedback: set[bytes], status: set[bytes]) -> tuple[str, int]:
    """The category of one RTPS datagram (``payload`` from the UDP payload on), and the samples
    of that category's writers that start in it (feedback data and status only)."""
    if payload[:4] != b'RTPS':
        return 'other', 0
    prefix = payload[8:20]
    submessages = _writer_ids(payload)
    writers = {prefix + entity for _, entity, _ in submessages}

    def samples(of: set[bytes]) -> int:
        return sum(starts and prefix + entity in of for _, entity, starts in submessages)

    if any(kind in (_DATA, _DATA_FRAG) and prefix + entity in feedback
           for kind, entity, _ in submessages):
        return 'feedback data', samples(feedback)
    if writers & feedback:
        return 'feedback gap/heartbeat', 0
    if writers & status:
        return 'status', samples(status)
    # Builtin endpoints have entity kinds with the two top bits set.
    if any(entity[3] & 0xc0 == 0xc0 for _, entity, _ in submessages):
        return 'discovery', 0
    return 'other', 0


def capture(interface: str, feedback: set[bytes], status: set[bytes],
            stop: threading.Event) -> dict[str, dict[str, Any]]:
    """Count received frames, and samples, on ``interface`` by category until ``stop`` is set."""
    sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(3))  # ETH_P_ALL
    sock.bind((interface, 0))
    sock.settimeout(0.2)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 * 1024 * 1024)
    frames: Counter[str] = Counter()
    octets: Counter[str] = Counter()
    first_fragment: dict[tuple[bytes, int], tuple[str, bool]] = {}
    received: set[tuple[bytes, int]] = set()  # (feedback writer GUID, sequence number)
    resent = Counter[str]()
    samples: Counter[str] = Counter()
    status_datagrams: list[int] = []
    print('SNIFFING', flush=True)
    while not stop.is_set():
        try:
            frame, address = sock.recvfrom(65535)
        except socket.timeout:
            continue
        if address[2] == socket.PACKET_OUTGOING:
            continue
        category, again, started = 'other', False, 0
        if frame[12:14] == b'\x08\x00' and frame[23] == 17:  # IPv4, UDP
            header = (frame[14] & 0x0f) * 4
            ident, fragment = struct.unpack('!HH', frame[18:22])
            key = (frame[26:30], ident)
            if fragment & 0x1fff:
                category, again = first_fragment.get(key, ('other', False))
            else:
                payload = frame[14 + header + 8:]
                category, started = classify(payload, feedback, status)
                if category == 'feedback data':
                    numbers = [n for n in data_sequence_numbers(payload) if n[0] in feedback]
                    again = bool(numbers) and all(n in received for n in numbers)
                    received.update(numbers)
                if category == 'status' and started:
                    status_datagrams.append(struct.unpack('!H', frame[14 + header + 4:
                                                                        14 + header + 6])[0])
                if fragment & 0x2000:  # more fragments follow
                    first_fragment[key] = (category, again)
        frames[category] += 1
        octets[category] += len(frame)
        if again:
            resent['bytes'] += len(frame)
            resent['packets'] += 1
        samples[category] += started
    counts: dict[str, dict[str, Any]] = {
        c: {'bytes': octets[c], 'packets': frames[c], 'samples': samples[c]} for c in CATEGORIES}
    counts['feedback data'].update(resent_bytes=resent['bytes'], resent_packets=resent['packets'])
    counts['status']['datagrams'] = status_datagrams
    return counts


def _received_udp(interface: str, stop: threading.Event,
                  listening: threading.Event) -> Iterator[tuple[int, bytes]]:
    """(UDP destination port, UDP payload) of each unfragmented IPv4 datagram received on
    ``interface`` until ``stop`` is set; sets ``listening`` once the socket is bound."""
    sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(3))  # ETH_P_ALL
    sock.bind((interface, 0))
    sock.settimeout(0.2)
    # Past net.core.rmem_max, as root may: a burst of large samples to several readers (4 MB of
    # results in tests/test_replies.py) overflowed 8 MB while this thread lagged.
    try:
        sock.setsockopt(socket.SOL_SOCKET, _SO_RCVBUFFORCE, 64 * 1024 * 1024)
    except PermissionError:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 * 1024 * 1024)
    listening.set()
    try:
        while not stop.is_set():
            try:
                frame, address = sock.recvfrom(65535)
            except socket.timeout:
                continue
            if (address[2] == socket.PACKET_OUTGOING or frame[12:14] != b'\x08\x00'
                    or frame[23] != 17):
                continue
            header = (frame[14] & 0x0f) * 4
            yield (struct.unpack('!H', frame[14 + header + 2:14 + header + 4])[0],
                   frame[14 + header + 8:])
    finally:
        sock.close()


class PortTraffic(NamedTuple):
    """What :func:`samples_by_port` saw for one UDP destination port."""
    #: (writer GUID, sequence number) -> the number of filter signatures its DATA or DATA_FRAG
    #: carried (None: no ``PID_CONTENT_FILTER_INFO``; a repair counts once, the last copy).
    samples: dict[tuple[bytes, int], Optional[int]]
    #: UDP payload bytes of the datagrams that name one of the writers (data, GAPs, heartbeats).
    octets: int
    #: Of those, the bytes of datagrams whose every DATA or fragment of the writers had come before
    #: (repairs the writer sent again after a NACK).
    resent_octets: int
    #: (writer GUID, sequence number) -> the serialized payload of its DATA (from the
    #: encapsulation header on; unfragmented samples only, the last copy).
    payloads: dict[tuple[bytes, int], bytes]


def _pieces(payload: bytes, writers: set[bytes]) -> set[tuple[bytes, int, int]]:
    """(writer GUID, sequence number, first fragment: 0 for a DATA) of each DATA and DATA_FRAG of
    ``writers`` in one RTPS datagram."""
    return {(writer, sequence,
             struct.unpack(order + 'I', body[20:24])[0] if kind == _DATA_FRAG else 0)
            for kind, _, order, body, writer, sequence in _samples(payload) if writer in writers}


def samples_by_port(interface: str, writers: set[bytes], stop: threading.Event,
                    listening: threading.Event) -> dict[int, PortTraffic]:
    """The DATA and DATA_FRAG submessages of ``writers`` received on ``interface`` until ``stop``
    is set, their payloads, and the bytes of the datagrams naming them, by UDP destination port
    (one port per reader's participant). Sets ``listening`` once the socket is bound.
    Unfragmented IPv4 datagrams only."""
    found: dict[int, PortTraffic] = {}
    received: dict[int, set[tuple[bytes, int, int]]] = {}
    for port, payload in _received_udp(interface, stop, listening):
        if payload[:4] != b'RTPS':
            continue
        prefix = payload[8:20]
        if not any(prefix + entity in writers for _, entity, _ in _writer_ids(payload)):
            continue
        pieces, before = _pieces(payload, writers), received.setdefault(port, set())
        again = bool(pieces) and pieces <= before
        before.update(pieces)
        seen = found.setdefault(port, PortTraffic({}, 0, 0, {}))
        found[port] = seen._replace(octets=seen.octets + len(payload),
                                    resent_octets=seen.resent_octets + again * len(payload))
        for kind, flags, order, body, writer, sequence in _samples(payload):
            if writer in writers:  # signatures as filter_signatures reads them (Q: inline QoS)
                signatures = _signatures(body, order) if flags & 0x02 else None
                seen.samples[(writer, sequence)] = signatures
                if kind == _DATA:
                    seen.payloads[(writer, sequence)] = _serialized(body, flags, order)
    return found


def _serialized(body: bytes, flags: int, order: str) -> bytes:
    """The serialized payload (from its encapsulation header on) of one DATA submessage body."""
    at = 4 + struct.unpack(order + 'H', body[2:4])[0]  # octetsToInlineQos counts from there
    if flags & 0x02:  # Q: an inline QoS parameter list, up to its sentinel
        for _, value, length in _inline_qos(body, order):
            at = value + length
    return body[at:] if flags & 0x04 else b''  # D: the submessage carries data


def data_by_port(interface: str, writers: set[bytes], stop: threading.Event,
                 listening: threading.Event) -> dict[int, dict[int, Optional[int]]]:
    """:func:`samples_by_port`'s samples by sequence number alone (for one writer): sequence
    number -> the number of filter signatures it carried."""
    return {port: {sequence: signatures for (_, sequence), signatures in seen.samples.items()}
            for port, seen in samples_by_port(interface, writers, stop, listening).items()}


def writer_datagrams_by_port(interface: str, writers: set[bytes], stop: threading.Event,
                             listening: threading.Event) -> dict[int, Counter[str]]:
    """The datagrams that name one of ``writers`` received on ``interface`` until ``stop`` is set,
    by UDP destination port (one port per reader's participant) and by what they carry of those
    writers: ``data`` (a DATA or DATA_FRAG, whatever else), ``heartbeat`` (HEARTBEATs only),
    ``gap`` (GAPs only) or ``gap+heartbeat``. Sets ``listening`` once the socket is bound.
    Unfragmented IPv4 datagrams only."""
    found: dict[int, Counter[str]] = {}
    for port, payload in _received_udp(interface, stop, listening):
        if payload[:4] != b'RTPS':
            continue
        prefix = payload[8:20]
        kinds = {kind for kind, entity, _ in _writer_ids(payload) if prefix + entity in writers}
        if not kinds:
            continue
        if kinds & {_DATA, _DATA_FRAG}:
            what = 'data'
        elif kinds == {_HEARTBEAT}:
            what = 'heartbeat'
        elif kinds == {_GAP}:
            what = 'gap'
        else:
            what = 'gap+heartbeat'
        found.setdefault(port, Counter())[what] += 1
    return found


def protected_by_port(interface: str, writers: set[bytes], stop: threading.Event,
                      listening: threading.Event) -> dict[int, Counter[str]]:
    """What the participant of ``writers`` sent under DDS Security, received on ``interface``
    until ``stop`` is set, by UDP destination port (one port per reader's participant):
    ``datagrams``, and of them ``srtps``, those protected whole (``SRTPS_PREFIX``); ``sec``, the
    submessages protected one by one (``SEC_PREFIX``) that can be seen (not inside an encrypted
    message); where the submessages can be seen (signed, not encrypted), ``named``, the datagrams
    with a submessage of one of ``writers``, and ``samples``, their DATA and first DATA_FRAG. Sets
    ``listening`` once the socket is bound. Unfragmented IPv4 datagrams only."""
    prefixes = {writer[:12] for writer in writers}
    found: dict[int, Counter[str]] = {}
    for port, payload in _received_udp(interface, stop, listening):
        if payload[:4] != b'RTPS' or payload[8:20] not in prefixes:
            continue
        kinds = [kind for kind, _, _ in _submessages(payload)]
        seen = found.setdefault(port, Counter())
        seen['datagrams'] += 1
        seen['srtps'] += _SRTPS_PREFIX in kinds
        seen['sec'] += kinds.count(_SEC_PREFIX)
        named = [starts for _, entity, starts in _writer_ids(payload)
                 if payload[8:20] + entity in writers]
        seen['named'] += bool(named)
        seen['samples'] += sum(named)
    return found


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
