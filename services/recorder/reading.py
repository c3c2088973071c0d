"""Reading recordings back: the ARROCH messages of a file in time order (camera frames with their JPEG
put back from the image channel), its metadata, and its channels' counts and time spans."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import msgspec
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from protocol.codec import decode, encode
from protocol.messages import CameraFrame, Message

from .topics import RAW_ENCODING, RAW_PREFIX, camera_image


@dataclass(frozen=True)
class ChannelStats:
    topic: str
    schema: str
    encoding: str
    messages: int
    first: float  # site-clock seconds of its first message
    last: float


@dataclass(frozen=True)
class Recorded:
    """One recorded ARROCH message: where it went (relative to the namespace), when, and its payload."""

    topic: str  # /arroch/<key below the namespace>
    time: float  # site-clock seconds
    payload: bytes
    message: Message


class RecordingError(ValueError):
    """A file that is not a readable ARROCH recording (the message names the file and the problem)."""


def _open(path: Path) -> BinaryIO:
    try:
        return open(path, "rb")
    except OSError as exc:
        raise RecordingError(f"{path}: cannot open: {exc.strerror}") from None


def metadata(path: Path) -> dict[str, str]:
    with _open(path) as f:
        try:
            for record in make_reader(f).iter_metadata():
                if record.name == "arroch":
                    return dict(record.metadata)
        except Exception as exc:
            raise RecordingError(f"{path}: not a readable MCAP file ({exc})") from None
    return {}


def channel_stats(path: Path) -> list[ChannelStats]:
    """Every channel with its message count and time span, from the file's summary (or a full read)."""
    with _open(path) as f:
        try:
            reader = make_reader(f)
            summary = reader.get_summary()
            spans: dict[int, list[int]] = {}
            counts: dict[int, int] = {}
            # Per-channel spans are not in the summary: one pass over the message headers.
            for _schema, channel, message in reader.iter_messages():
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
        first, last = spans.get(cid, [0, 0])
        out.append(
            ChannelStats(
                channel.topic,
                schema.name if schema else "",
                channel.message_encoding,
                counts.get(cid, 0),
                first / 1e9,
                last / 1e9,
            )
        )
    return sorted(out, key=lambda c: c.topic)


def messages(path: Path, *, start: float | None = None, end: float | None = None) -> Iterator[Recorded]:
    """The recorded ARROCH messages in log-time order; camera frames come with their JPEG again.

    A frame's JPEG is stored once, in its ``/camera/<cid>/image`` message of the same time (the raw
    frame is kept without it); the two are paired here, whichever of them the file gives first.
    """
    with _open(path) as f:
        reader = make_reader(f)
        factory = DecoderFactory()
        decoders: dict[int, Callable[[bytes], Any]] = {}  # schema id -> protobuf decoder
        images: dict[tuple[str, int], bytes] = {}  # (camera, log time) -> JPEG waiting for its frame
        frames: dict[tuple[str, int], tuple[str, CameraFrame]] = {}  # frames waiting for their JPEG
        kwargs = {
            "start_time": None if start is None else int(start * 1e9),
            "end_time": None if end is None else int(end * 1e9),
        }
        try:
            for schema, channel, message in reader.iter_messages(log_time_order=True, **kwargs):
                topic = channel.topic
                if channel.message_encoding == RAW_ENCODING and topic.startswith(RAW_PREFIX):
                    msg = decode(message.data)
                    if isinstance(msg, CameraFrame) and not msg.jpeg:
                        slot = (msg.camera, message.log_time)
                        if slot in images:
                            yield _frame_with(topic, message.log_time, msg, images.pop(slot))
                        else:
                            frames[slot] = (topic, msg)
                        continue
                    yield Recorded(topic, message.log_time / 1e9, bytes(message.data), msg)
                elif topic.startswith("/camera/") and topic.endswith("/image"):
                    camera = topic.split("/")[2]
                    if topic != camera_image(camera):
                        continue
                    decoder = decoders.get(channel.schema_id)
                    if decoder is None:
                        decoder = decoders[channel.schema_id] = factory.decoder_for(channel.message_encoding, schema)
                    jpeg = decoder(message.data).data
                    slot = (camera, message.log_time)
                    if slot in frames:
                        raw_topic, frame = frames.pop(slot)
                        yield _frame_with(raw_topic, message.log_time, frame, jpeg)
                    else:
                        images.clear()  # only the newest image can still meet its frame
                        images[slot] = jpeg
        except RecordingError:
            raise
        except Exception as exc:
            raise RecordingError(f"{path}: cannot read the recording ({exc})") from None


def _frame_with(topic: str, log_time: int, frame: CameraFrame, jpeg: bytes) -> Recorded:
    whole = msgspec.structs.replace(frame, jpeg=bytes(jpeg))
    return Recorded(topic, log_time / 1e9, encode(whole), whole)
