"""Reading recordings back: the ARROCH messages of a file in time order, each with the bytes it
travelled as (from the wire store, :mod:`.wire`; camera frames with their JPEG put back from the
image channel), the file's metadata, and its channels' counts and time spans.

Times given and returned here are site seconds: a log time less the file's site-time origin
(:mod:`.timebase`).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from mcap.reader import McapReader, make_reader
from mcap_protobuf.decoder import DecoderFactory

from protocol.codec import decode
from protocol.messages import Message

from .profile import METADATA
from .timebase import CLOCK_METADATA, ORIGIN_KEY, ns
from .topics import MESSAGE_PREFIX, message_topic
from .wire import WireRecord, read_batches, with_jpeg


@dataclass(frozen=True)
class ChannelStats:
    topic: str
    schema: str
    encoding: str
    messages: int
    first: float  # site seconds of its first message (negative: written before site time 0)
    last: float


@dataclass(frozen=True)
class Recorded:
    """One recorded ARROCH message: where it went (``/arroch/<key below the namespace>``), when, its bytes."""

    topic: str
    time: float  # site seconds
    payload: bytes  # as it travelled
    message: Message


class RecordingError(ValueError):
    """A file that is not a readable ARROCH recording (the message names the file and the problem)."""


def _open(path: Path) -> BinaryIO:
    try:
        return open(path, "rb")
    except OSError as exc:
        raise RecordingError(f"{path}: cannot open: {exc.strerror}") from None


def _metadata(reader: McapReader, name: str) -> dict[str, str]:
    for record in reader.iter_metadata():
        if record.name == name:
            return dict(record.metadata)
    return {}


def _origin(reader: McapReader) -> int:
    return int(_metadata(reader, CLOCK_METADATA).get(ORIGIN_KEY, 0))


def metadata(path: Path) -> dict[str, str]:
    """The ``arroch`` metadata record (namespace, site, profile, clock), and the site-time origin."""
    with _open(path) as f:
        try:
            reader = make_reader(f)
            found = _metadata(reader, METADATA)
            found.update(_metadata(reader, CLOCK_METADATA))
            return found
        except Exception as exc:
            raise RecordingError(f"{path}: not a readable MCAP file ({exc})") from None


def channel_stats(path: Path) -> list[ChannelStats]:
    """Every channel with its message count and time span in site seconds."""
    with _open(path) as f:
        try:
            reader = make_reader(f)
            summary = reader.get_summary()
            origin = _origin(reader)
            spans: dict[int, list[int]] = {}
            counts: dict[int, int] = {}
            # Per-channel spans are not in the summary: one pass over the message headers.
            for _schema, channel, message in reader.iter_messages(log_time_order=False):
                span = spans.setdefault(channel.id, [message.log_time, message.log_time])
                span[0] = min(span[0], message.log_time)
                span[1] = max(span[1], message.log_time)
                counts[channel.id] = counts.get(channel.id, 0) + 1
        except Exception as exc:
            raise RecordingError(f"{path}: not a readable MCAP file ({exc})") from None
    out = []
    channels = summary.channels if summary else {}
    schemas = summary.schemas if summary else {}
    for cid, channel in channels.items():
        schema = schemas.get(channel.schema_id)
        first, last = spans.get(cid, [origin, origin])
        out.append(
            ChannelStats(
                channel.topic,
                schema.name if schema else "",
                channel.message_encoding,
                counts.get(cid, 0),
                (first - origin) / 1e9,
                (last - origin) / 1e9,
            )
        )
    return sorted(out, key=lambda c: c.topic)


def _images(reader: McapReader, start: int | None, end: int | None) -> Iterator[tuple[str, int, bytes]]:
    """(camera, log time, JPEG) of every ``/camera/<cid>/image`` message, in log-time order."""
    factory = DecoderFactory()
    decoders: dict[int, Any] = {}
    topics = [c.topic for c in (reader.get_summary().channels.values()) if _camera_of(c.topic)]
    for schema, channel, message in reader.iter_messages(topics=topics, start_time=start, end_time=end):
        decoder = decoders.get(channel.id)
        if decoder is None:
            decoder = decoders[channel.id] = factory.decoder_for(channel.message_encoding, schema)
        yield _camera_of(channel.topic), message.log_time, bytes(decoder(message.data).data)


def message_topics(path: Path) -> list[str]:
    """The topics of the recorded ARROCH messages (``/arroch/<key below the namespace>``), from the
    file's summary (nothing else is read)."""
    with _open(path) as f:
        try:
            summary = make_reader(f).get_summary()
        except Exception as exc:
            raise RecordingError(f"{path}: not a readable MCAP file ({exc})") from None
    channels = summary.channels.values() if summary else []
    return sorted({c.topic for c in channels if c.topic.startswith(MESSAGE_PREFIX)})


def _camera_of(topic: str) -> str:
    parts = topic.split("/")
    return parts[2] if len(parts) == 4 and parts[1] == "camera" and parts[3] == "image" else ""


def _records(reader: McapReader, path: Path) -> list[WireRecord]:
    records = list(read_batches((a.name, a.media_type, a.data) for a in reader.iter_attachments()))
    if not records and any(c.message_encoding == "msgpack" for c in reader.get_summary().channels.values()):
        raise RecordingError(
            f"{path}: recorded by an older arroch (its messages are msgpack channels, with no wire store): "
            "read or replay it with the version that recorded it"
        )
    records.sort(key=lambda r: r.at)  # stable: messages of one log time stay in the order they came
    return records


def messages(path: Path, *, start: float | None = None, end: float | None = None) -> Iterator[Recorded]:
    """The recorded ARROCH messages in log-time order (``start``/``end``: site seconds), each with the
    bytes it travelled as. A camera frame whose image is missing (a file cut short) is left out."""
    with _open(path) as f:
        try:
            reader = make_reader(f)
            if reader.get_summary() is None:
                raise RecordingError(f"{path}: not a finished recording (no summary: its recorder was killed?)")
            origin = _origin(reader)
            lo = None if start is None else origin + ns(start)
            hi = None if end is None else origin + ns(end)
            images = _images(reader, lo, hi)
            waiting: dict[tuple[str, int], bytes] = {}  # images read ahead, by (camera, log time)
            for record in _records(reader, path):
                if (lo is not None and record.at < lo) or (hi is not None and record.at > hi):
                    continue
                payload = record.payload
                if record.cut >= 0:
                    jpeg = _image_for(record, images, waiting)
                    if jpeg is None:
                        continue
                    payload = with_jpeg(record, jpeg)
                yield Recorded(message_topic(record.key), (record.at - origin) / 1e9, payload, decode(payload))
        except RecordingError:
            raise
        except Exception as exc:
            raise RecordingError(f"{path}: cannot read the recording ({exc})") from None


def _image_for(
    record: WireRecord, images: Iterator[tuple[str, int, bytes]], waiting: dict[tuple[str, int], bytes]
) -> bytes | None:
    """The JPEG logged with a frame (same camera, same log time): images are read in step with the records."""
    camera = record.key.split("/")[1]
    for old in [slot for slot in waiting if slot[1] < record.at]:
        del waiting[old]  # their frames are behind us
    while (camera, record.at) not in waiting:
        image = next(images, None)
        if image is None:
            return None
        if image[1] >= record.at:
            waiting[(image[0], image[1])] = image[2]
        if image[1] > record.at:
            break
    return waiting.pop((camera, record.at), None)
