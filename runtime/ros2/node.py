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
import weakref
from collections.abc import Callable, Iterator
from typing import Any

import zenoh
import zenoh.ext

from runtime.service import Service

from . import types as ros
from .attachment import Attachment, gid_of
from .keys import Qos, TopicNaming, full_topic

# rmw_zenoh numbers nodes and entities from one counter per context (one Zenoh session), so that
# two nodes of one process never announce the same <node id>/<entity id>: one counter per service.
_COUNTERS: weakref.WeakKeyDictionary[Service, Iterator[int]] = weakref.WeakKeyDictionary()
_COUNTERS_LOCK = threading.Lock()


def next_entity_id(service: Service) -> int:
    with _COUNTERS_LOCK:
        counter = _COUNTERS.setdefault(service, itertools.count(0))
        return next(counter)


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
        self._zid = str(service.session.info.zid())
        self._node_id = next_entity_id(service)
        if naming.rmw_zenoh:
            service.hold(
                service.session.liveliness().declare_token(
                    naming.node_token(self._zid, self._node_id, self.namespace, name)
                )
            )

    def topic(self, topic: str) -> str:
        return full_topic(self.namespace, topic)

    def _token(self, kind: str, topic: str, typename: str, qos: Qos) -> str | None:
        if not self.naming.rmw_zenoh:
            return None
        token = self.naming.endpoint_token(
            self._zid,
            self._node_id,
            next_entity_id(self.service),
            kind,
            self.namespace,
            self.name,
            topic,
            typename,
            qos=qos,
        )
        self.service.hold(self.service.session.liveliness().declare_token(token))
        return token

    def publisher(self, topic: str, typename: str, *, reliable: bool = True, depth: int = 10) -> RosPublisher:
        """A keep-last publisher of ``typename`` on ``topic`` (relative names are in the node's
        namespace). Under congestion its samples are dropped, never blocking the caller, as
        rmw_zenoh does for keep-last publishers (it blocks only keep-all reliable ones): a stale
        cmd_vel is worth nothing, and a blocked control loop would stop sending zero velocities."""
        name = self.topic(topic)
        token = self._token("MP", name, typename, Qos(reliable, depth))
        key = self.naming.data_key(name, typename)
        publisher = self.service.hold(
            self.service.session.declare_publisher(
                key,
                congestion_control=zenoh.CongestionControl.DROP,
                reliability=zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT,
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
        transient_local: bool = False,
    ) -> str:
        """Call ``handler(message, key)`` on the service's worker for each ``typename`` sample on
        ``topic``; samples that are not valid CDR of that type are counted as bad messages.
        ``ordered`` (default): queued in arrival order with the service's other ordered subscriptions.
        ``transient_local``: the publisher keeps its last samples (Nav2's ``amcl_pose``): the token
        says so and the subscription asks for them, as rmw_zenoh's transient-local subscription does."""
        name = self.topic(topic)
        qos = Qos(depth=1, transient_local=True) if transient_local else Qos()
        self._token("MS", name, typename, qos)
        key = self.naming.subscription_key(name, typename)
        self.service.subscribe_foreign(
            key,
            lambda payload: ros.deserialize(payload, typename),
            handler,
            latest=latest,
            ordered=ordered,
            history=transient_local,
        )
        return key
