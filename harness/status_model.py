"""The status topic's size model: bytes of a ``GoalStatusArray`` in CDR and on the wire, and the
status messages a run of goals makes (docs/BENCHMARKS.md, "The status topic", "The model").

:mod:`harness.client` counts the CDR bytes of the status messages a client takes with
:func:`status_array_size`; ``benchmarks/status.py`` sets :func:`predict` next to what it captured;
tests/test_status_size.py checks both against rclpy's serialization and captured frames.
"""

from __future__ import annotations

import bisect
import math
from typing import Optional, Sequence

#: CDR bytes of an ``action_msgs/GoalStatusArray``: the 4-byte encapsulation header and the 4-byte
#: sequence length, then per goal a 16-byte UUID, an 8-byte stamp and a 1-byte status, padded to 28
#: bytes but for the last (checked against ``serialize_message`` in tests/test_status_size.py).
STATUS_ARRAY_HEADER = 8
STATUS_ENTRY = 28
_STATUS_LAST_PADDING = 3

#: Status messages rclpy's ActionServer publishes per goal that succeeds: accepted, executing,
#: succeeded (``ServerGoalHandle._update_state`` and ``_execute_goal_request``). Expiring goals
#: publishes nothing.
MESSAGES_PER_GOAL = 3

#: Bytes of a status sample on the wire besides its CDR payload, as captured on a client's veth
#: (decoded from the frames): Ethernet 14, IPv4 20, UDP 8, RTPS header 20, INFO_TS 12, the DATA
#: submessage's header 24, a piggybacked HEARTBEAT 32 (the writer's keep-last-1 history is always
#: full), and 60 of the vendor submessage 0x80 that Fast DDS built with statistics appends to every
#: datagram it sends. The payload is padded to 4 bytes.
WIRE_OVERHEAD = 14 + 20 + 8 + 20 + 12 + 24 + 32 + 60
#: The INFO_DST submessage, which the writer adds when it has a single reader (with several it
#: sends each the same datagram, addressed to none).
INFO_DST = 16
#: Bytes of IPv4 payload per fragment at the veth's MTU of 1500, and the headers each further
#: fragment repeats (Ethernet and IPv4).
IP_FRAGMENT_PAYLOAD = 1480
IP_FRAGMENT_HEADERS = 14 + 20


def status_array_size(entries: int) -> int:
    """Serialized (CDR) size of a ``GoalStatusArray`` listing ``entries`` goals."""
    if entries == 0:
        return STATUS_ARRAY_HEADER
    return STATUS_ARRAY_HEADER + STATUS_ENTRY * entries - _STATUS_LAST_PADDING


def wire_bytes(entries: int, readers: int = 2) -> int:
    """Bytes on the wire of one status sample that lists ``entries`` goals, at one of ``readers``.

    The CDR payload (:func:`status_array_size`, padded to 4) with :data:`WIRE_OVERHEAD` (and
    :data:`INFO_DST` for a single reader), and the headers of each IPv4 fragment after the first.
    """
    frame = (WIRE_OVERHEAD + (INFO_DST if readers == 1 else 0)
             + 4 * math.ceil(status_array_size(entries) / 4))
    fragments = max(1, math.ceil((frame - 14 - 20) / IP_FRAGMENT_PAYLOAD))
    return frame + IP_FRAGMENT_HEADERS * (fragments - 1)


def entries_in(datagram: float, readers: int = 2) -> float:
    """Goal entries of a status sample whose UDP datagram is ``datagram`` bytes (inverse of
    :func:`wire_bytes`, with a piggybacked heartbeat)."""
    udp_overhead = (WIRE_OVERHEAD - 14 - 20 + (INFO_DST if readers == 1 else 0)
                    + STATUS_ARRAY_HEADER)
    return (datagram - udp_overhead) / STATUS_ENTRY


def predict(accepted_at: Sequence[float], duration_s: float, result_timeout_s: float,
            held_before: int = 0, held_before_s: Optional[float] = None,
            readers: int = 2) -> dict[str, float]:
    """The status messages of a run, and their entries and bytes, by the model.

    Goal ``i`` is accepted at ``accepted_at[i]`` (s, in the order given for equal times), runs
    ``duration_s`` and is then held ``result_timeout_s`` more. Each goal makes
    :data:`MESSAGES_PER_GOAL` messages: two at acceptance (accepted, executing), one when it
    finishes; each lists the goals held at that moment, plus ``held_before`` goals (such as
    probes) that stay until ``held_before_s`` (default: ``result_timeout_s``).

    :returns: ``messages``, ``entries`` (summed over messages), ``max_entries``, ``cdr_bytes``
        and ``wire_bytes`` (per client, every message delivered to each of ``readers``).
    """
    accepted = sorted(accepted_at)
    held_until = result_timeout_s if held_before_s is None else held_before_s
    expiries = sorted(a + duration_s + result_timeout_s for a in accepted)
    entries: list[int] = []

    def held(t: float, accepted_so_far: int) -> int:
        expired = bisect.bisect_right(expiries, t)
        return accepted_so_far - expired + (held_before if t < held_until else 0)

    for i, a in enumerate(accepted):
        entries += [held(a, i + 1)] * 2
    for a in accepted:
        finish = a + duration_s
        entries.append(held(finish, bisect.bisect_right(accepted, finish)))
    return {'messages': len(entries), 'entries': sum(entries),
            'max_entries': max(entries, default=0),
            'cdr_bytes': sum(status_array_size(e) for e in entries),
            'wire_bytes': sum(wire_bytes(e, readers) for e in entries)}
