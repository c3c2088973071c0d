"""rmw_zenoh's per-sample attachment: what a ROS 2 subscriber reads as the message's info.

Layout (rmw_zenoh_cpp ``attachment_helpers.cpp``, written with ``zenoh::ext::Serializer``):
``int64 sequence_number``, ``int64 source_timestamp`` (ns, the publisher's system clock), then the
16-byte publisher GID as a sequence (LEB128 length 16, then the bytes); little endian. 33 bytes.
"""

from __future__ import annotations

import hashlib
import struct
from dataclasses import dataclass

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
    """A 16-byte GID for the entity announced by ``token``. rmw_zenoh derives its GIDs from the
    token with XXH3-128; we use BLAKE2b-128 (no XXH3 in the standard library): unique and stable
    per entity, but not the value a ROS 2 node would compute for the same token."""
    return hashlib.blake2b(token.encode(), digest_size=GID_SIZE).digest()
