"""The page ↔ server protocol over the WebSocket, and its limits.

Binary messages carry images; text messages are JSON objects with a ``type``.

Page → server:

- a camera frame: ``b"ARF2"``, the frame's sequence number (uint32, little-endian), the device's
  gravity at capture in the camera frame (three float32, little-endian, OpenCV axes, pointing down,
  m/s²; NaN when unknown), then a baseline or progressive JPEG of at most :data:`MAX_FRAME_BYTES`
  bytes and :data:`MAX_SIDE` pixels a side. ``b"ARF1"`` frames (seq, JPEG: no gravity) are still taken;
- ``{"type": "feedback", "id": n, "kind": "<library entry>", "params": {name: value}, "wall": t}``: one
  choice from the constraint library (values: integers, short strings or finite numbers; ``wall``, the
  page's clock when sent, optional: a study records it);
- ``{"type": "ping", "t": x}``: answered with ``{"type": "pong", "t": x}`` (link round trip);
- on a study server (``--study-trial``), the study page's messages (:mod:`.study_wire`).

Server → page:

- ``hello`` once: the client's camera id, its mode, the site's geometry for the map, the constraint
  library the running restrictor serves (null until one answers; then a ``{"type": "library", "entries"}``
  message), the live constraints, frame limits;
- ``overlay`` per processed frame (its ``seq``; pose quality; the primitives in frame pixels);
- ``ack`` per feedback (``status`` accepted / refused / no answer, the restrictor's ``reason``);
- ``world`` a few times a second (robots, intents, doors: the map view) and ``constraints`` on change;
- viewer mode: the sim's frames as binary ``b"ARV1"`` + seq + JPEG, each followed by its ``overlay``;
- study mode: ``study`` (the trial's state: consent, puzzle, where she is, the site clock's rate,
  questionnaire) on every change, and ``refused`` (``what``, ``reason``) to a page whose request the
  study turned down.

The page's text messages are declared as msgspec Structs (:data:`PAGE_MESSAGES`) and checked like
every other input (a refusal names the field: ``feedback: params.minutes: expected int or float or
str, got list``). Anything else — a binary message that is not a frame, a JPEG the header of which
does not parse or is too large, text that is not a JSON object of a known type, a malformed
feedback — is a protocol violation: :class:`Violation` carries the WebSocket close code, and the
session closes that client.
"""

from __future__ import annotations

import json
import math
import struct
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any

import msgspec
from msgspec import Meta, Struct

from protocol.messages import Overlay
from protocol.validation import field_error

from .study_wire import STUDY_MESSAGES, StudyMessage

FRAME_MAGIC = b"ARF1"
GRAVITY_FRAME_MAGIC = b"ARF2"
VIEWER_MAGIC = b"ARV1"
HEADER = struct.Struct("<4sI")
GRAVITY = struct.Struct("<3f")
#: A gravity reading longer than this (m/s²) is not an accelerometer's: the frame is refused.
MAX_GRAVITY = 100.0
MAX_FRAME_BYTES = 2 * 1024 * 1024
MAX_SIDE = 1920
MIN_SIDE = 16
MAX_TEXT_BYTES = 16 * 1024
MAX_PARAMS = 32
MAX_STRING = 64

# WebSocket close codes (RFC 6455 §7.4.1).
CLOSE_UNSUPPORTED = 1003  # a binary message that is not a camera frame
CLOSE_BAD_DATA = 1007  # text that is not JSON
CLOSE_POLICY = 1008  # a known shape broken, or limits exceeded
CLOSE_TOO_BIG = 1009

# JPEG start-of-frame markers (baseline, extended, progressive, lossless; Huffman and arithmetic).
_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
_STANDALONE = {0x01, *range(0xD0, 0xD8)}  # markers without a length field


class Violation(Exception):
    """A client broke the protocol; ``code`` is the WebSocket close code to send."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason


@dataclass(frozen=True)
class Frame:
    seq: int
    jpeg: bytes
    width: int
    height: int
    gravity: tuple[float, float, float] | None = None  # camera frame, pointing down; None: unknown


def jpeg_size(data: bytes) -> tuple[int, int]:
    """(width, height) from a JPEG's start-of-frame header, without decoding the image.

    Checked before any decoding so that a tiny file claiming 65535×65535 pixels never makes the
    decoder allocate gigabytes. Raises :class:`Violation` when this is not a JPEG."""
    n = len(data)
    if n < 4 or data[0] != 0xFF or data[1] != 0xD8:
        raise Violation(CLOSE_UNSUPPORTED, "frame is not a JPEG (no start-of-image marker)")
    i = 2
    while i + 4 <= n:
        if data[i] != 0xFF:
            raise Violation(CLOSE_UNSUPPORTED, f"JPEG marker expected at byte {i}")
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in _STANDALONE:
            i += 2
            continue
        if marker in (0xD9, 0xDA):  # end of image, or scan data before any frame header
            break
        length = (data[i + 2] << 8) | data[i + 3]
        if length < 2:
            break
        if marker in _SOF:
            if i + 9 > n:
                break
            height = (data[i + 5] << 8) | data[i + 6]
            width = (data[i + 7] << 8) | data[i + 8]
            return width, height
        i += 2 + length
    raise Violation(CLOSE_UNSUPPORTED, "JPEG has no readable frame header")


def parse_frame(message: bytes, magic: bytes = FRAME_MAGIC) -> Frame:
    """A binary WebSocket message as a camera frame, within the limits."""
    if len(message) < HEADER.size:
        raise Violation(CLOSE_UNSUPPORTED, f"binary message of {len(message)} bytes is not a frame")
    tag, seq = HEADER.unpack_from(message)
    start, gravity = HEADER.size, None
    if magic == FRAME_MAGIC and tag == GRAVITY_FRAME_MAGIC:
        if len(message) < HEADER.size + GRAVITY.size:
            raise Violation(CLOSE_UNSUPPORTED, f"binary message of {len(message)} bytes is not a frame")
        gravity = _gravity(GRAVITY.unpack_from(message, HEADER.size))
        start += GRAVITY.size
    elif tag != magic:
        raise Violation(CLOSE_UNSUPPORTED, "binary message is not a frame (bad magic)")
    jpeg = bytes(message[start:])
    if len(jpeg) > MAX_FRAME_BYTES:
        raise Violation(CLOSE_TOO_BIG, f"frame of {len(jpeg)} bytes exceeds {MAX_FRAME_BYTES}")
    width, height = jpeg_size(jpeg)
    if not (MIN_SIDE <= width <= MAX_SIDE and MIN_SIDE <= height <= MAX_SIDE):
        raise Violation(CLOSE_TOO_BIG, f"frame of {width}x{height} pixels is outside {MIN_SIDE}..{MAX_SIDE} a side")
    return Frame(seq=seq, jpeg=jpeg, width=width, height=height, gravity=gravity)


def _gravity(values: tuple[float, float, float]) -> tuple[float, float, float] | None:
    """A frame's gravity: None when unknown (NaN, or all zero); a :class:`Violation` when absurd."""
    if not all(math.isfinite(v) for v in values) or not any(values):
        return None
    if math.sqrt(sum(v * v for v in values)) > MAX_GRAVITY:
        raise Violation(CLOSE_POLICY, f"frame gravity {values} is longer than {MAX_GRAVITY} m/s²")
    return (float(values[0]), float(values[1]), float(values[2]))


def pack_frame(
    seq: int, jpeg: bytes, magic: bytes = FRAME_MAGIC, gravity: tuple[float, float, float] | None = None
) -> bytes:
    """A frame message as the page sends it (``ARF2`` with gravity when given, else ``ARF1``)."""
    if gravity is not None and magic == FRAME_MAGIC:
        return HEADER.pack(GRAVITY_FRAME_MAGIC, seq & 0xFFFFFFFF) + GRAVITY.pack(*gravity) + jpeg
    return HEADER.pack(magic, seq & 0xFFFFFFFF) + jpeg


# --------------------------------------------------------------------------- JSON from the page


ParamName = Annotated[str, Meta(min_length=1, max_length=MAX_STRING)]
ParamValue = (
    Annotated[int, Meta(gt=-(2**53), lt=2**53)]  # what a page's JavaScript numbers hold exactly
    | Annotated[float, Meta(ge=-sys.float_info.max, le=sys.float_info.max)]  # finite
    | Annotated[str, Meta(max_length=MAX_STRING)]
)


class FeedbackRequest(Struct, frozen=True, kw_only=True):
    """``{"type": "feedback", ...}``: the shape of a feedback request; its meaning is the restrictor's to judge."""

    id: Annotated[int, Meta(ge=0, lt=2**53)]
    kind: Annotated[str, Meta(min_length=1, max_length=MAX_STRING)]
    params: Annotated[dict[ParamName, ParamValue], Meta(max_length=MAX_PARAMS)]
    wall: Annotated[float, Meta(ge=0.0, lt=1e10)] = 0.0  # the page's clock when sent (study records); 0: unknown


class Ping(Struct, frozen=True, kw_only=True):
    """``{"type": "ping", "t": x}``: answered with a pong carrying ``t`` back."""

    t: int | float


PAGE_MESSAGES: dict[str, type[Struct]] = {"feedback": FeedbackRequest, "ping": Ping, **STUDY_MESSAGES}


def parse_text(text: str) -> FeedbackRequest | Ping | StudyMessage:
    """A text message from the page, checked against its type's declaration (:data:`PAGE_MESSAGES`)."""
    if len(text) > MAX_TEXT_BYTES:
        raise Violation(CLOSE_TOO_BIG, f"text message of {len(text)} characters exceeds {MAX_TEXT_BYTES}")
    try:
        data = msgspec.json.decode(text)
    except (msgspec.DecodeError, RecursionError):
        raise Violation(CLOSE_BAD_DATA, "text message is not JSON") from None
    if not isinstance(data, dict) or not isinstance(data.get("type"), str):
        raise Violation(CLOSE_POLICY, "text message is not an object with a 'type'")
    kind = data["type"]
    cls = PAGE_MESSAGES.get(kind)
    if cls is None:
        raise Violation(CLOSE_POLICY, f"unknown message type {kind[:32]!r}")
    try:
        return msgspec.convert(data, cls)
    except msgspec.ValidationError as exc:
        raise Violation(CLOSE_POLICY, f"{kind}: {field_error(exc, cls, data)}") from None


# --------------------------------------------------------------------------- JSON to the page

#: Overlay layers the page does not draw: it shows pose quality in its own status bar and its
#: feedback buttons as HTML.
PAGE_SKIPS_LAYERS = frozenset({"status", "ui"})


def _r(value: float) -> float:
    return round(float(value), 1)


def overlay_json(
    overlay: Overlay,
    *,
    reason: str = "",
    intrinsics: str = "",
    server_ms: float = 0.0,
    source: str = "browser",
    gravity: tuple[float, float, float] | list[float] | None = None,
) -> str:
    """An Overlay as the page's ``overlay`` message (primitives rounded to 0.1 px, short keys)."""
    prims = []
    for p in overlay.primitives:
        if p.layer in PAGE_SKIPS_LAYERS:
            continue
        item: dict[str, Any] = {
            "k": p.kind,
            "p": [[_r(x), _r(y)] for x, y in p.points],
            "c": list(p.color),
            "w": p.width,
            "l": p.layer,
        }
        if p.radius:
            item["r"] = p.radius
        if p.text:
            item["t"] = p.text
        if p.style != "solid":
            item["s"] = p.style
        prims.append(item)
    return json.dumps(
        {
            "type": "overlay",
            "source": source,
            "camera": overlay.camera,
            "seq": overlay.frame_seq,
            "width": overlay.width,
            "height": overlay.height,
            "ok": overlay.ok,
            "position": overlay.position,
            "quaternion": overlay.quaternion,
            "tags": overlay.tags,
            "rmse": round(overlay.reprojection_rmse, 3),
            "lost_age": round(overlay.lost_age, 2),
            "reason": reason,
            "intrinsics": intrinsics,
            "server_ms": round(server_ms, 1),
            "gravity": [round(float(v), 3) for v in gravity] if gravity else None,  # what the pose was solved with
            "primitives": prims,
        },
        separators=(",", ":"),
    )


def site_json(site) -> dict[str, Any]:  # noqa: ANN001 (protocol.site.Site)
    """The site's geometry for the map view: rooms, walls, doors with their leaves, passages, tags."""
    doors = {}
    for did, leaf in site.door_leaves.items():
        opening = site.openings[did]
        doors[did] = {
            "hinge": list(leaf.hinge),
            "closed": list(leaf.tip(open=False)),
            "open": list(leaf.tip(open=True)),
            "human_operated": opening.human_operated,
        }
    return {
        "name": site.name,
        "bounds": list(site.bounds),
        "rooms": {rid: list(room.rect) for rid, room in site.rooms.items()},
        "walls": [[*w.a, *w.b] for w in site.walls],
        "doors": doors,
        "passages": {pid: [list(p) for p in o.endpoints] for pid, o in site.passages.items()},
        "landmarks": [[lm.tag, lm.position[0], lm.position[1]] for lm in site.landmarks],
        "human": list(site.human.position),
        "robot_radius": site.params.robot_radius,
    }


MAX_MAP_PATH = 200  # points of an intent sent to the map


def world_json(snapshot, colour: Callable[[str], list[int]]) -> dict[str, Any]:  # noqa: ANN001 (WorldSnapshot)
    """A WorldSnapshot for the map: robots (in their overlay colours), their intents from now on
    (decimated), door states."""
    robots = {
        rid: {
            "x": round(r.x, 3),
            "y": round(r.y, 3),
            "theta": round(r.theta, 3),
            "state": r.state,
            "color": colour(rid),
        }
        for rid, r in snapshot.robots.items()
    }
    intents = {}
    for rid, rows in snapshot.intents.items():
        if len(rows) == 0:
            continue
        future = rows[rows[:, 0] >= snapshot.now] if rows[-1, 0] >= snapshot.now else rows[-1:]
        step = max(1, math.ceil(len(future) / MAX_MAP_PATH))
        pts = future[::step]
        if len(future) and (len(future) - 1) % step:
            pts = list(pts) + [future[-1]]
        intents[rid] = [[round(float(r[1]), 3), round(float(r[2]), 3), round(float(r[0]), 2)] for r in pts]
    doors = {did: bool(state.open) for did, state in snapshot.doors.items()}
    return {"type": "world", "now": snapshot.now, "robots": robots, "intents": intents, "doors": doors}
