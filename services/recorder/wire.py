"""The wire store: every message's bytes as they travelled, kept in the recording for ``arroch replay``.

They are MCAP attachments of the recording itself (one file holds the whole run), which viewers do
not list: every channel stays in an encoding Foxglove decodes (the messages are there as JSON too).
An attachment ``arroch/wire/<n>`` (media type :data:`MEDIA_TYPE`) holds a batch of records in
arrival order, each ``[key below the namespace, log time (ns), payload]``, as a msgpack array,
compressed with zstd (attachments are not compressed by MCAP itself). A batch is written when it
holds :data:`BATCH_BYTES` or is :data:`BATCH_SECONDS` old, and when the recording closes.

A camera frame's JPEG is kept once, in its ``/camera/<cid>/image`` message of the same log time:
its record holds the payload without those bytes and ``cut``, where they were; reading puts them
back, so the payload comes out exactly as it travelled.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import msgspec
import zstandard

ATTACHMENT_PREFIX = "arroch/wire/"
MEDIA_TYPE = "application/vnd.arroch.wire+msgpack+zstd"
BATCH_BYTES = 1 << 20
BATCH_SECONDS = 5.0  # wall seconds: at most this much is lost when the recorder is killed


class WireRecord(msgspec.Struct, array_like=True):
    key: str  # below the namespace: robot/r0/pose
    at: int  # log time, ns
    payload: bytes
    cut: int = -1  # where a camera frame's JPEG was taken out (-1: nothing was)


_encode = msgspec.msgpack.Encoder().encode
_decode = msgspec.msgpack.Decoder(list[WireRecord]).decode


def without_jpeg(payload: bytes, jpeg: bytes) -> tuple[bytes, int]:
    """A frame's payload without its JPEG, and where it was (-1 if the JPEG is not in it as such)."""
    cut = payload.find(jpeg) if jpeg else -1
    if cut < 0:
        return payload, -1
    return payload[:cut] + payload[cut + len(jpeg) :], cut


def with_jpeg(record: WireRecord, jpeg: bytes) -> bytes:
    """The payload as it travelled: the JPEG put back where it was taken out."""
    return record.payload[: record.cut] + jpeg + record.payload[record.cut :]


class WireWriter:
    """Collects records and hands each finished batch to ``attach(name, log_time, create_time, data)``."""

    def __init__(self, attach: Callable[[str, int, int, bytes], None]) -> None:
        self._attach = attach
        self._batch: list[WireRecord] = []
        self._size = 0
        self._since = 0.0
        self._count = 0
        self._compress = zstandard.ZstdCompressor(level=3).compress

    def add(self, record: WireRecord) -> None:
        if not self._batch:
            self._since = time.monotonic()
        self._batch.append(record)
        self._size += len(record.payload) + len(record.key) + 16
        if self._size >= BATCH_BYTES:
            self.flush()
        else:
            self.flush_if_old()

    def flush_if_old(self) -> None:
        if self._batch and time.monotonic() - self._since >= BATCH_SECONDS:
            self.flush()

    def flush(self) -> None:
        if not self._batch:
            return
        batch, self._batch, self._size = self._batch, [], 0
        name = f"{ATTACHMENT_PREFIX}{self._count:06d}"
        self._count += 1
        self._attach(name, min(r.at for r in batch), max(r.at for r in batch), self._compress(_encode(batch)))


def read_batches(attachments: Iterator[tuple[str, str, bytes]]) -> Iterator[WireRecord]:
    """The records of ``(name, media type, data)`` attachments, in batch order (others skipped)."""
    decompress = zstandard.ZstdDecompressor().decompress
    batches = sorted((name, data) for name, media, data in attachments if media == MEDIA_TYPE)
    for _name, data in batches:
        yield from _decode(decompress(data))
