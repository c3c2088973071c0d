"""A rosbag2 folder (MCAP storage) as one ROS 2 distribution's ``ros2 bag`` writes and reads it.

``rosbags`` (which reads every version) writes only versions 8 and 9; Humble's rosbag2 reads at most
version 5 and refuses the QoS profiles of version 9. So the bag is written here, per distribution,
with the ``mcap`` writer and ``rosbags``' message definitions, hashes and QoS dumps. The formats,
from rosbag2's own sources (``ros2/rosbag2``, branches ``humble`` and ``jazzy``):

- ``metadata.yaml`` ``version`` (``rosbag2_storage/.../bag_metadata.hpp``): Humble 5, Jazzy 9;
- ``offered_qos_profiles``: Humble a string holding YAML, its enums as integers (``metadata_io.cpp``,
  ``rosbag2_transport/src/.../qos.cpp``); Jazzy a YAML list, enums by name (``include/.../yaml.hpp``,
  ``rosbag2_storage/src/.../qos.cpp``);
- ``type_description_hash`` (RIHS01, version 7), ``custom_data`` (6), ``ros_distro`` (8): Jazzy only;
- the MCAP file's ``rosbag2`` metadata record (``rosbag2_storage_mcap/src/mcap_storage.cpp``): Humble
  ``ROS_DISTRO``, Jazzy ``serialized_metadata`` (the bag's metadata as YAML); each channel's metadata:
  ``offered_qos_profiles``, and in Jazzy ``topic_type_hash``.

Schemas are ``ros2msg`` definitions from the distribution's ``rosbags`` type store; the CDR bytes are
``runtime.ros2.types``' (the messages written here have the same fields in Humble and Jazzy, which a
test checks by reading a Humble bag back with Humble's definitions). The storage file is
``<folder>/<folder name>_0.mcap``, as ``ros2 bag record`` names it.
"""

from __future__ import annotations

import io
import shutil
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2.metadata import dump_qos_v8, dump_qos_v9
from rosbags.typesys import Stores, get_typestore
from ruamel.yaml import YAML

from runtime.ros2 import types as ros


@dataclass(frozen=True)
class Distro:
    name: str
    version: int  # the metadata version its rosbag2 writes
    store: Stores

    @cached_property
    def typestore(self) -> Any:
        return get_typestore(self.store)

    @property
    def qos_as_text(self) -> bool:
        return self.version < 9

    @property
    def has_hashes(self) -> bool:
        return self.version >= 7


DISTROS: dict[str, Distro] = {
    "humble": Distro("humble", 5, Stores.ROS2_HUMBLE),
    "jazzy": Distro("jazzy", 9, Stores.ROS2_JAZZY),
}
DEFAULT_DISTRO = "jazzy"  # the LTS release current when this was written

_NONE = QosTime(0, 0)  # deadline, lifespan, lease: not set (the middleware's default)


def qos(*, depth: int = 10, reliable: bool = True, latched: bool = False) -> Qos:
    """A publisher's QoS as ``ros2 bag play`` recreates it (keep last ``depth``)."""
    return Qos(
        QosHistory.KEEP_LAST,
        depth,
        QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
        QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
        _NONE,
        _NONE,
        QosLiveliness.AUTOMATIC,
        _NONE,
        False,
    )


def _yaml(data: Any) -> str:
    """Block-style YAML, long strings on one line (as yaml-cpp writes them for rosbag2)."""
    yaml = YAML(typ="safe")
    yaml.default_flow_style = False
    yaml.width = 1 << 16
    out = io.StringIO()
    yaml.dump(data, out)
    return out.getvalue()


@dataclass
class _Topic:
    channel_id: int
    msgtype: str
    qos: Qos
    count: int = 0


class BagWriter:
    """Write messages (``runtime.ros2.types`` objects) to a new rosbag2 folder; ``close()`` finishes it."""

    def __init__(self, folder: Path, distro: Distro, custom_data: dict[str, str] | None = None) -> None:
        if folder.exists():
            raise ValueError(f"{folder}: a ROS 2 bag folder must not exist yet (a bag is never overwritten)")
        self.folder = folder
        self.distro = distro
        self.custom_data = dict(custom_data or {})
        self.storage = folder / f"{folder.name}_0.mcap"
        self._writer: McapWriter | None = None
        self._file: Any = None
        self._schemas: dict[str, int] = {}
        self._topics: dict[str, _Topic] = {}
        self._first = 2**63 - 1
        self._last = 0
        self._created = False  # this writer made the folder (only then may abort() remove it)

    def open(self) -> None:
        self.folder.mkdir(parents=True)
        self._created = True
        self._file = open(self.storage, "xb")
        self._writer = McapWriter(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library="arroch")
        if self.distro.version < 9:  # Humble's plugin notes the distribution as it opens the file
            self._writer.add_metadata("rosbag2", {"ROS_DISTRO": self.distro.name})

    def write(self, topic: str, msgtype: str, msg: Any, at: int, offered: Qos | None = None) -> None:
        """``msg`` of ``msgtype`` on ``topic`` at log time ``at`` (ns); ``offered``: the topic's QoS."""
        assert self._writer is not None, "open() first"
        entry = self._topics.get(topic)
        if entry is None:
            entry = self._topics[topic] = self._add_topic(topic, msgtype, offered or qos())
        elif entry.msgtype != msgtype:
            raise ValueError(f"topic {topic}: {msgtype} after {entry.msgtype}")
        self._writer.add_message(
            entry.channel_id, log_time=at, publish_time=at, data=ros.serialize(msg, msgtype), sequence=entry.count
        )
        entry.count += 1
        self._first = min(self._first, at)
        self._last = max(self._last, at)

    def _add_topic(self, topic: str, msgtype: str, offered: Qos) -> _Topic:
        assert self._writer is not None
        store = self.distro.typestore
        schema_id = self._schemas.get(msgtype)
        if schema_id is None:
            definition, _digest = store.generate_msgdef(msgtype, ros_version=2)
            schema_id = self._schemas[msgtype] = self._writer.register_schema(msgtype, "ros2msg", definition.encode())
        metadata = {"offered_qos_profiles": self._qos_text([offered])}
        if self.distro.has_hashes:
            metadata["topic_type_hash"] = store.hash_rihs01(msgtype)
        channel_id = self._writer.register_channel(topic, "cdr", schema_id, metadata)
        return _Topic(channel_id, msgtype, offered)

    def _qos_text(self, profiles: list[Qos]) -> str:
        """The profiles as one YAML text (Humble's ``metadata.yaml`` and every MCAP channel keep them so)."""
        dumped = YAML(typ="safe").load(dump_qos_v8(profiles)) if self.distro.qos_as_text else dump_qos_v9(profiles)
        return _yaml(dumped).strip()

    def metadata(self) -> dict[str, Any]:
        """The ``rosbag2_bagfile_information`` of ``metadata.yaml``, in the distribution's version."""
        count = sum(t.count for t in self._topics.values())
        start = self._first if count else 0
        duration = self._last - self._first if count else 0
        topics = []
        for name, entry in self._topics.items():
            meta: dict[str, Any] = {
                "name": name,
                "type": entry.msgtype,
                "serialization_format": "cdr",
                "offered_qos_profiles": (
                    self._qos_text([entry.qos]) if self.distro.qos_as_text else dump_qos_v9([entry.qos])
                ),
            }
            if self.distro.has_hashes:
                meta["type_description_hash"] = self.distro.typestore.hash_rihs01(entry.msgtype)
            topics.append({"topic_metadata": meta, "message_count": entry.count})
        info: dict[str, Any] = {
            "version": self.distro.version,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": count,
            "topics_with_message_count": topics,
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.storage.name],
            "files": [
                {
                    "path": self.storage.name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": count,
                }
            ],
        }
        if self.distro.version >= 6:
            info["custom_data"] = dict(self.custom_data)
        if self.distro.version >= 8:
            info["ros_distro"] = self.distro.name
        return info

    def close(self) -> None:
        """Finish the storage file (summary, index) and write ``metadata.yaml``."""
        if self._writer is None:
            return
        info = self.metadata()
        if self.custom_data:  # what was recorded, for every distribution (Humble's metadata has no custom_data)
            self._writer.add_metadata("arroch", dict(self.custom_data))
        if self.distro.version >= 9:  # Jazzy's plugin keeps the bag's metadata inside the file too
            self._writer.add_metadata("rosbag2", {"serialized_metadata": _yaml(info)})
        self._writer.finish()
        self._file.close()
        self._writer = None
        (self.folder / "metadata.yaml").write_text(_yaml({"rosbag2_bagfile_information": info}), encoding="utf-8")

    def abort(self) -> None:
        """Remove the folder: a bag that could not be written whole must not block the next attempt."""
        if self._file is not None:
            self._file.close()
        self._writer = None
        if self._created:
            shutil.rmtree(self.folder, ignore_errors=True)
