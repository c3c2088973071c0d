"""A ROS 2 node's publishers and subscriptions on a Service's Zenoh session (no ROS installed).

``RosNode(service, naming, "arroch_robot_r0")`` announces the node (rmw_zenoh: a ``NN`` token) and
each endpoint (``MP``/``MS`` tokens) so that ``ros2 topic list``/``ros2 node list`` on a ROS 2
machine running rmw_zenoh see them; every sample it publishes carries rmw_zenoh's attachment.
With the ``ros2dds`` key format it only puts and subscribes plain CDR on the topic's name.
Everything declared is undeclared when the service closes.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from protocol.service import Service

from . import types as ros
from .attachment import Attachment, gid_of
from .keys import TopicNaming, full_topic


class RosPublisher:
    """Publishes one topic's messages (``publish(msg)``); thread-safe."""

    def __init__(self, publisher: zenoh.Publisher, typename: str, gid: bytes | None) -> None:
        self._publisher = publisher
        self.typename = typename
        self._gid = gid  # None: no attachment (ros2dds)
        self._seq = itertools.count(1)
        self._lock = threading.Lock()  # one sequence number per sample, in order
        self.published = 0

    def publish(self, msg: Any) -> bytes:
        payload = ros.serialize(msg, self.typename)
        with self._lock:
            if self._gid is None:
                self._publisher.put(payload)
            else:
                attachment = Attachment(next(self._seq), time.time_ns(), self._gid).encode()
                self._publisher.put(payload, attachment=attachment)
            self.published += 1
        return payload


class RosNode:
    """One ROS 2 node (name, namespace) living on ``service``'s session."""

    def __init__(self, service: Service, naming: TopicNaming, name: str, namespace: str = "/") -> None:
        self.service = service
        self.naming = naming
        self.name = name
        self.namespace = namespace if namespace.startswith("/") else "/" + namespace
        self._entities = itertools.count(1)
        self._zid = str(service.session.info.zid())
        self._node_id = 0
        if naming.rmw_zenoh:
            service.hold(
                service.session.liveliness().declare_token(
                    naming.node_token(self._zid, self._node_id, self.namespace, name)
                )
            )

    def topic(self, topic: str) -> str:
        return full_topic(self.namespace, topic)

    def _token(self, kind: str, topic: str, typename: str, reliable: bool) -> str | None:
        if not self.naming.rmw_zenoh:
            return None
        token = self.naming.endpoint_token(
            self._zid,
            self._node_id,
            next(self._entities),
            kind,
            self.namespace,
            self.name,
            topic,
            typename,
            reliable=reliable,
        )
        self.service.hold(self.service.session.liveliness().declare_token(token))
        return token

    def publisher(self, topic: str, typename: str, *, reliable: bool = True) -> RosPublisher:
        """A publisher of ``typename`` on ``topic`` (relative names are in the node's namespace)."""
        name = self.topic(topic)
        token = self._token("MP", name, typename, reliable)
        key = self.naming.data_key(name, typename)
        publisher = self.service.hold(
            self.service.session.declare_publisher(
                key,
                congestion_control=zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP,
                express=True,
            )
        )
        return RosPublisher(publisher, typename, gid_of(token) if token else None)

    def subscribe(
        self,
        topic: str,
        typename: str,
        handler: Callable[[Any, str], None],
        *,
        latest: bool = False,
        ordered: bool = True,
    ) -> str:
        """Call ``handler(message, key)`` on the service's worker for each ``typename`` sample on
        ``topic``; samples that are not valid CDR of that type are counted as bad messages.
        ``ordered`` (default): queued in arrival order with the service's other ordered subscriptions."""
        name = self.topic(topic)
        self._token("MS", name, typename, True)
        key = self.naming.subscription_key(name, typename)
        self.service.subscribe_foreign(
            key, lambda payload: ros.deserialize(payload, typename), handler, latest=latest, ordered=ordered
        )
        return key
