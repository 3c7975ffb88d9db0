# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Proof that a filter change has reached the writers of another process.

A content filter change travels to the writers by discovery, and the middleware acknowledges
nothing: until the change arrives, a writer applies its previous filter. Discovery is one ordered,
reliable stream per participant, though, and a remote service can only reply to a client once it
has matched the client's response reader. So the reply of a service of that process, to a client
created *after* the change, proves that every writer there has processed the change
(docs/INTERNALS.md, "Proof of arrival").

:class:`ServiceProbe` is that round trip. It is polled, not waited on: the parameter event handler
polls it in a blocking loop, the action client from a timer of its own callback group.
"""

from __future__ import annotations

from typing import Any, Optional, Sequence

from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_services_default

from cft_action._rclpy_compat import new_rcl_client

__all__ = ['GUID_PREFIX_LEN', 'ServiceProbe', 'node_participant', 'participant_of']

#: The length of a GUID prefix, which names the participant, at the start of an endpoint GID.
GUID_PREFIX_LEN = 12

#: How long a probe request may go unanswered before it is sent again, first and at most: a server
#: that has not yet matched the client's request writer drops the request, and one that has not
#: matched its response reader drops the reply. The client sees the server's endpoints at once,
#: the server sees the client's a discovery round later, so the first request is often dropped,
#: while a held goal request waits for the reply: the interval starts short and doubles. A
#: repeated request is harmless.
PROBE_FIRST_RESEND_S = 0.02
PROBE_MAX_RESEND_S = 0.5


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
