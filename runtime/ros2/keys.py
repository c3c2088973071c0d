"""Zenoh key expressions of ROS 2 topics, in the two formats ROS 2 uses on Zenoh.

- ``rmw_zenoh`` (ROS 2's own Zenoh middleware, ros2/rmw_zenoh docs/design.md): a sample's key is
  ``<domain>/<topic without its leading slash>/<DDS type name>/<RIHS01 type hash>``, e.g.
  ``0/r0/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_9c45...``. Nodes find each other through
  liveliness tokens ``@ros2_lv/<domain>/<session id>/<node id>/<entity id>/<kind>/<enclave>/
  <namespace>/<node name>[/<topic>/<type>/<hash>/<qos>]`` (kind ``NN`` node, ``MP`` publisher,
  ``MS`` subscription; names with ``/`` replaced by ``%``, an empty namespace as ``%``), as built by
  rmw_zenoh_cpp's ``liveliness_utils.cpp`` (``Entity``, ``qos_to_keyexpr``).
- ``ros2dds`` (``zenoh-bridge-ros2dds``, bridging a DDS ROS 2 system): the key is the topic name
  without its leading slash (behind the bridge's optional ``namespace``), the payload plain CDR,
  no attachment and no tokens of ours (the bridge announces DDS endpoints itself).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from .types import HASH_NOT_SUPPORTED, dds_type_name, type_hash

KEY_FORMATS = ("rmw_zenoh", "ros2dds")
ADMIN_SPACE = "@ros2_lv"


@dataclass(frozen=True)
class Qos:
    """The QoS of an endpoint as far as its token tells it (always keep-last)."""

    reliable: bool = True
    depth: int = 10
    transient_local: bool = False

    def chunk(self) -> str:
        """The token's QoS chunk as rmw_zenoh_cpp's ``qos_to_keyexpr`` writes it: eleven values
        ``rel:dur:hist,depth:dl_s,dl_ns:ls_s,ls_ns:liv,lease_s,lease_ns``, each left empty when it
        equals rmw_zenoh's default (reliable, volatile, keep-last, depth 42, infinite deadline and
        lifespan, automatic liveliness with an infinite lease)."""
        reliability = "" if self.reliable else "2"  # RMW_QOS_POLICY_RELIABILITY_BEST_EFFORT
        durability = "1" if self.transient_local else ""  # RMW_QOS_POLICY_DURABILITY_TRANSIENT_LOCAL
        depth = "" if self.depth == 42 else str(self.depth)
        return f"{reliability}:{durability}:,{depth}:,:,:,,"


QOS_RELIABLE = Qos().chunk()  # "::,10:,:,:,,"
QOS_BEST_EFFORT = Qos(reliable=False, depth=1).chunk()  # "2::,1:,:,:,,"
_TOPIC = re.compile(r"^/?[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*$")


def full_topic(namespace: str, topic: str) -> str:
    """The fully qualified name of ``topic`` in ``namespace`` (``/r0`` + ``odom`` -> ``/r0/odom``;
    an absolute ``/tf`` stays as it is). Raises ValueError for a name ROS 2 would refuse."""
    if not _TOPIC.match(topic):
        raise ValueError(f"topic {topic!r} is not a valid ROS 2 topic name")
    if topic.startswith("/"):
        return topic
    ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
    if ns and not _TOPIC.match(ns):
        raise ValueError(f"namespace {namespace!r} is not a valid ROS 2 namespace")
    return f"{ns}/{topic}"


def mangle(name: str) -> str:
    """A ROS name as one key chunk (``/`` -> ``%``), as rmw_zenoh does."""
    return name.replace("/", "%") if name else "%"


class TopicNaming:
    """Keys and liveliness tokens of ROS 2 topics for one key format, domain and bridge namespace."""

    def __init__(
        self, key_format: str = "rmw_zenoh", domain: int = 0, bridge_namespace: str = "", *, hashless: bool = False
    ) -> None:
        if key_format not in KEY_FORMATS:
            raise ValueError(f"key format {key_format!r}: expected one of {', '.join(KEY_FORMATS)}")
        if not 0 <= domain <= 232:
            raise ValueError(f"ROS domain id {domain}: expected 0..232")
        self.key_format = key_format
        self.domain = domain
        self.bridge_namespace = bridge_namespace.strip("/")
        self.hashless = hashless  # Humble's rmw_zenoh: TypeHashNotSupported instead of RIHS01 hashes

    def type_hash(self, typename: str) -> str:
        return HASH_NOT_SUPPORTED if self.hashless else type_hash(typename)

    @property
    def rmw_zenoh(self) -> bool:
        return self.key_format == "rmw_zenoh"

    def data_key(self, topic: str, typename: str) -> str:
        """Where samples of ``topic`` (fully qualified) of ``typename`` are put."""
        name = topic.strip("/")
        if self.rmw_zenoh:
            return f"{self.domain}/{name}/{dds_type_name(typename)}/{self.type_hash(typename)}"
        return f"{self.bridge_namespace}/{name}" if self.bridge_namespace else name

    def subscription_key(self, topic: str, typename: str) -> str:
        """What to subscribe to for ``topic``: in rmw_zenoh, any type hash of that type (a distro
        whose definition hashes differently, or Humble's nodes which put no hash, still arrive)."""
        if self.rmw_zenoh:
            return f"{self.domain}/{topic.strip('/')}/{dds_type_name(typename)}/*"
        return self.data_key(topic, typename)

    def node_token(self, zid: str, node_id: int, namespace: str, node: str) -> str:
        return "/".join(
            (ADMIN_SPACE, str(self.domain), zid, str(node_id), str(node_id), "NN", "%", mangle(namespace), node)
        )

    def endpoint_token(
        self,
        zid: str,
        node_id: int,
        entity_id: int,
        kind: str,
        namespace: str,
        node: str,
        topic: str,
        typename: str,
        *,
        qos: Qos = Qos(),
    ) -> str:
        """The token announcing a publisher (``kind="MP"``) or subscription (``"MS"``) of ``topic``."""
        if kind not in ("MP", "MS"):
            raise ValueError(f"endpoint kind {kind!r}: expected MP or MS")
        return "/".join(
            (
                ADMIN_SPACE,
                str(self.domain),
                zid,
                str(node_id),
                str(entity_id),
                kind,
                "%",
                mangle(namespace),
                node,
                mangle(topic),
                dds_type_name(typename),
                self.type_hash(typename),
                qos.chunk(),
            )
        )
