"""rmw_zenoh's per-sample attachment: what a ROS 2 subscriber reads as the message's info.

Layout (rmw_zenoh_cpp ``attachment_helpers.cpp``, written with ``zenoh::ext::Serializer``):
``int64 sequence_number``, ``int64 source_timestamp`` (ns, the publisher's system clock), then the
16-byte publisher GID as a sequence (LEB128 length 16, then the bytes); little endian. 33 bytes.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import xxhash

GID_SIZE = 16
_HEAD = struct.Struct("<qq")


@dataclass(frozen=True)
class Attachment:
    sequence_number: int
    source_timestamp: int  # ns
    gid: bytes

    def encode(self) -> bytes:
        if len(self.gid) != GID_SIZE:
            raise ValueError(f"publisher GID must be {GID_SIZE} bytes, got {len(self.gid)}")
        return _HEAD.pack(self.sequence_number, self.source_timestamp) + bytes((GID_SIZE,)) + self.gid

    @classmethod
    def decode(cls, data: bytes) -> Attachment:
        if len(data) != _HEAD.size + 1 + GID_SIZE or data[_HEAD.size] != GID_SIZE:
            raise ValueError(f"not an rmw_zenoh attachment ({len(data)} bytes)")
        seq, stamp = _HEAD.unpack_from(data)
        return cls(seq, stamp, bytes(data[_HEAD.size + 1 :]))


def gid_of(token: str) -> bytes:
    """The 16-byte GID of the entity announced by ``token``, as rmw_zenoh_cpp computes it
    (``Entity::gid``): XXH3-128 of the token, its 128-bit value stored low byte first; so a ROS 2
    graph cache finds in our samples' attachments the GIDs it computed from our tokens."""
    return xxhash.xxh3_128_digest(token.encode())[::-1]
