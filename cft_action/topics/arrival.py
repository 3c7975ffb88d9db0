# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Proof that a filter change has reached the writers of another process.

A content filter change travels to the writers by discovery, and the middleware acknowledges
nothing: until the change arrives, a writer applies its previous filter. Discovery is one ordered,
reliable stream per participant, though, and a remote service can only reply to a client once it
has matched the client's response reader. So the reply of a service of that process, to a client
created *after* the change, proves that every writer there has processed the change
(docs/INTERNALS.md, "Proof of arrival").

- :class:`ServiceProbe` is that round trip, to one service.
- :class:`ArrivalProof` is one proof: a probe for every other participant that hosts a writer,
  polled until each has answered.
- :class:`ArrivalGate` is what every owner of a filtered reader asks: which of the reader's filter
  versions the writers are proven to apply. The parameter event handler waits on it in a blocking
  loop (:meth:`ArrivalGate.wait`); the action client polls it from a timer of its own callback
  group (:meth:`ArrivalGate.begin`, :meth:`ArrivalGate.poll`), while its goal requests wait in
  :class:`cft_action.action._held_goals.HeldGoals`.
"""

from __future__ import annotations

import time
from typing import Any, Callable, Mapping, NamedTuple, Optional, Sequence

from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_services_default

from cft_action._rclpy_compat import new_rcl_client

__all__ = ['ArrivalGate', 'ArrivalProof', 'GUID_PREFIX_LEN', 'ProbeTarget', 'RemotePublishers',
           'ServiceProbe', 'Targets', 'node_participant', 'participant_of']

#: The length of a GUID prefix, which names the participant, at the start of an endpoint GID.
GUID_PREFIX_LEN = 12

#: How long a probe request may go unanswered before it is sent again, first and at most: a server
#: that has not yet matched the client's request writer drops the request, and one that has not
#: matched its response reader drops the reply. The client sees the server's endpoints at once,
#: the server sees the client's a discovery round later, so the first request is often dropped,
#: while a held goal request waits for the reply: the interval starts short and doubles. A
#: repeated request is answered as the first (a server that has not matched the response reader
#: yet waits up to 100 ms for it in rmw_fastrtps, then drops the reply), so its owner bounds how
#: long a proof is polled this often.
PROBE_FIRST_RESEND_S = 0.02
PROBE_MAX_RESEND_S = 0.5

#: How long a proof probes one service of a participant before it tries the participant's next one
#: (a node that is not spun, or whose server has not matched the probe's client yet).
PROBE_TURN_S = 2.0

#: How often :meth:`ArrivalGate.wait` polls its proof.
WAIT_POLL_S = 0.01


def participant_of(endpoint_gid: Any) -> bytes:
    """The GUID prefix of an endpoint's GID (a ``TopicEndpointInfo.endpoint_gid``)."""
    return bytes(endpoint_gid[:GUID_PREFIX_LEN])


def node_participant(node: Node, topics: Sequence[str]) -> Optional[bytes]:
    """The participant of ``node``: that of one of its endpoints on ``topics``, or None if none.

    A node's own endpoints are in the graph as soon as they exist; every node of a context shares
    one participant.
    """
    name, namespace = node.get_name(), node.get_namespace()
    for topic in topics:
        for info in (*node.get_publishers_info_by_topic(topic),
                     *node.get_subscriptions_info_by_topic(topic)):
            if (info.node_name, info.node_namespace) == (name, namespace):
                return participant_of(info.endpoint_gid)
    return None


class ServiceProbe:
    """One request to a service, from a client of its own, sent until it is answered.

    Create it after the filter change that it is to prove: the client's endpoints are announced
    after the change.

    :param node: The node whose participant changed the filter.
    :param srv_type: The service type.
    :param service_name: The fully qualified service name.
    :param request: The request; it must be harmless to the server, since it may arrive twice.
    :param qos_profile: The client's QoS, the service's default when omitted.
    """

    def __init__(self, node: Node, srv_type: Any, service_name: str, request: Any,
                 qos_profile: Optional[QoSProfile] = None) -> None:
        self.service_name = service_name
        self._srv_type = srv_type
        self._request = request
        self._sent_at: Optional[float] = None
        self._resend_after = PROBE_FIRST_RESEND_S
        self._client = new_rcl_client(node, srv_type, service_name,
                                      qos_profile or qos_profile_services_default)

    def poll(self, now: float) -> bool:
        """Send the request, or send it again, and return True once a reply has come.

        :param now: ``time.monotonic()``.
        """
        if self.answered():
            return True
        self.send_if_due(now)
        return False

    def answered(self) -> bool:
        """Take a reply, if one has come, without sending anything."""
        with self._client:
            header, _ = self._client.take_response(self._srv_type.Response)
        return header is not None

    def send_if_due(self, now: float) -> None:
        """Send the request if it was never sent, or went unanswered for the resend interval."""
        if self._sent_at is not None:
            if now - self._sent_at < self._resend_after:
                return
            self._resend_after = min(2 * self._resend_after, PROBE_MAX_RESEND_S)
        with self._client:
            if self._client.service_server_is_available():
                self._client.send_request(self._request)
                self._sent_at = now

    def destroy(self) -> None:
        """Destroy the probe's client."""
        self._client.destroy_when_not_in_use()


class RemotePublishers:
    """The publishers of a topic in participants other than the node's own.

    :param node: The node whose participant is "own".
    :param topic: The topic of the publishers.
    :param own_topics: Topics on which the node has an endpoint, to find its participant by.
    """

    def __init__(self, node: Node, topic: str, own_topics: Sequence[str]) -> None:
        self._node = node
        self._topic = topic
        self._own_topics = own_topics
        self._own: Optional[bytes] = None

    def own(self) -> Optional[bytes]:
        """The node's participant, or None while the graph does not show it yet."""
        if self._own is None:
            self._own = node_participant(self._node, self._own_topics)
        return self._own

    def by_participant(self) -> dict[bytes, list[Any]]:
        """Each other participant's publishers (``TopicEndpointInfo``), in the graph's order."""
        own = self.own()
        found: dict[bytes, list[Any]] = {}
        for info in self._node.get_publishers_info_by_topic(self._topic):
            participant = participant_of(info.endpoint_gid)
            if participant != own:
                found.setdefault(participant, []).append(info)
        return found

    def gids(self) -> list[Any]:
        """The GIDs (``endpoint_gid``) of the other participants' publishers."""
        return [info.endpoint_gid for infos in self.by_participant().values() for info in infos]

    def any(self) -> bool:
        """Whether a publisher may be in another participant: True while the own one is unknown."""
        return self.own() is None or bool(self.by_participant())

    def seen(self) -> bool:
        """Whether the graph shows a publisher of the topic, in any participant."""
        return bool(self._node.get_publishers_info_by_topic(self._topic))


class ProbeTarget(NamedTuple):
    """A service whose reply proves arrival: its type, name, a harmless request and the QoS."""

    srv_type: Any
    service_name: str
    request: Any
    qos_profile: Optional[QoSProfile] = None


#: Each participant to hear from, mapped to the services that can answer for it, tried in turn.
#: An empty list keeps the participant pending (its nodes' names are not known yet).
Targets = Callable[[], Mapping[bytes, Sequence[ProbeTarget]]]


class ArrivalProof:
    """One proof of arrival: probes created after a change, polled until every participant answered.

    The participants are asked anew at each poll, so one that appears meanwhile is waited for too.

    :param node: The node whose participant changed the filter.
    :param targets: The participants to hear from, and their services.
    :param version: The filter version that an answer proves.
    """

    def __init__(self, node: Node, targets: Targets, version: int) -> None:
        self.version = version
        self.polled_since: Optional[float] = None
        self._node = node
        self._targets = targets
        self._probes: dict[str, tuple[bytes, ServiceProbe]] = {}  # service -> (participant, probe)
        self._turns: dict[bytes, tuple[int, float]] = {}  # participant -> (service index, since)
        self._answered: set[bytes] = set()
        # Created at once, not at the first poll: discovery of the probes' clients starts now.
        self._probe_pending(time.monotonic(), send=False)

    def poll(self, now: float) -> bool:
        """Take the replies that came, send or resend the requests; True once all have answered.

        :param now: ``time.monotonic()``.
        """
        if self.polled_since is None:
            self.polled_since = now
        for participant, probe in self._probes.values():
            if participant not in self._answered and probe.answered():
                self._answered.add(participant)
        return not self._probe_pending(now, send=True)

    def destroy(self) -> None:
        """Destroy the probes' clients."""
        for _, probe in self._probes.values():
            probe.destroy()
        self._probes.clear()

    def _probe_pending(self, now: float, *, send: bool) -> bool:
        """Probe each participant that has not answered, on its service of the turn."""
        pending = {participant: services for participant, services in self._targets().items()
                   if participant not in self._answered}
        for participant, services in pending.items():
            if not services:
                continue
            index, since = self._turns.setdefault(participant, (0, now))
            if now - since >= PROBE_TURN_S and len(services) > 1:
                index, since = index + 1, now
                self._turns[participant] = (index, since)
            target = services[index % len(services)]
            if target.service_name not in self._probes:
                self._probes[target.service_name] = (participant, ServiceProbe(
                    self._node, target.srv_type, target.service_name, target.request,
                    target.qos_profile))
            if send:
                self._probes[target.service_name][1].send_if_due(now)
        return bool(pending)


class ArrivalGate:
    """Which versions of a reader's filter the writers of other processes are proven to apply.

    A version is the reader's update count (``FilteredReader.updates``): 0 is the filter the reader
    was created with, which a writer receives with the match itself; version ``n`` is proven by a
    proof begun after the ``n``-th update. Whether a writer has matched the reader at all needs a
    proof too where the reader was announced after the endpoints that show the writer's process
    ready (``proven=-1``): the action client's feedback reader, which rmw_fastrtps recreates with
    the first filter, after the goal service's endpoints, so that a goal round trip does not prove
    that the server's feedback writer has it yet.

    Its owner serializes the calls (it holds its reader's lock), except :meth:`wait`, which takes
    ``lock`` only to record the outcome.

    :param node: The node whose participant changed the filter.
    :param targets: The participants to hear from, and their services.
    :param lock: The owner's lock.
    :param proven: The latest version taken as proven at the start: 0, or -1 until a proof of the
        reader itself.
    """

    def __init__(self, node: Node, targets: Targets, lock: Any, *, proven: int = 0) -> None:
        self._node = node
        self._targets = targets
        self._lock = lock
        self._confirmed = proven
        self._proof: Optional[ArrivalProof] = None
        self.timeouts = 0

    @property
    def confirmed(self) -> int:
        """The latest version proven to have arrived."""
        return self._confirmed

    def is_confirmed(self, version: int) -> bool:
        """Whether ``version`` is proven to have arrived."""
        return version <= self._confirmed

    # --- polled, from the owner's timer ----------------------------------------------------------

    @property
    def proving(self) -> bool:
        """Whether a proof begun with :meth:`begin` is running."""
        return self._proof is not None

    def begin(self, version: int) -> None:
        """Begin a proof of ``version`` now, unless one is running."""
        if self._proof is None:
            self._proof = ArrivalProof(self._node, self._targets, version)

    def poll(self, now: float, timeout: Optional[float]) -> Optional[bool]:
        """Poll the running proof: True once it came, False once it timed out, else None.

        Either outcome ends the proof; one that came confirms its version, one that timed out is
        counted in :attr:`timeouts`.

        :param now: ``time.monotonic()``.
        :param timeout: Seconds that the proof may take, from its first poll: a caller that spins
            only later gives it no chance before. None: as long as it takes.
        """
        proof = self._proof
        if proof is None:
            return None
        came = proof.poll(now)
        if came:
            self._confirmed = max(self._confirmed, proof.version)
        elif (timeout is not None and proof.polled_since is not None
              and now - proof.polled_since >= timeout):
            self.timeouts += 1
        else:
            return None
        self.end()
        return came

    def end(self) -> None:
        """Drop the running proof, if any."""
        if self._proof is not None:
            self._proof.destroy()
            self._proof = None

    # --- waited for, in the caller's thread ------------------------------------------------------

    def wait(self, version: int, timeout_sec: Optional[float]) -> bool:
        """Block until a proof of ``version``, begun now, came; it is then confirmed.

        :param timeout_sec: Seconds to wait; forever if ``None`` or negative.
        :return: False on timeout.
        """
        proof = ArrivalProof(self._node, self._targets, version)
        try:
            while not proof.poll(time.monotonic()):
                if (timeout_sec is not None and timeout_sec >= 0 and proof.polled_since is not None
                        and time.monotonic() - proof.polled_since >= timeout_sec):
                    return False
                time.sleep(WAIT_POLL_S)
        finally:
            proof.destroy()
        with self._lock:
            self._confirmed = max(self._confirmed, version)
        return True
