"""Typed messages of the ARROCH wire format (DESIGN §4).

Every message carries the envelope ``v`` (schema major version), ``type``, ``src`` (sender id),
``seq`` (per-sender counter) and ``stamp`` (seconds on the site clock). ``src``, ``seq`` and
``stamp`` default to empty values so code can build a message and let the publisher
(:class:`protocol.service.Service`) stamp it.

Trajectories travel as rows ``[t, x, y, theta]`` rather than maps: about 3x cheaper to
encode, and the row length is checked on decode.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from .schema import Json, Scalar, spec

# Bounds shared by several messages. Site coordinates are metres; 10 km covers any building.
COORD = 10_000.0
ANGLE = 1_000.0  # radians; unwrapped headings stay far below this
TIME = 1e10  # seconds on the site clock (sim time from 0, or Unix time)
MAX_TRAJECTORY = 20_000

ROBOT_STATES = ("idle", "moving", "waiting_at_door", "loading", "unloading", "done", "failed")
PRIMITIVE_KINDS = ("line", "polyline", "polygon", "circle", "text", "arrow")
LINE_STYLES = ("solid", "xray", "dashed")
AWAITING = ("", "plan", "feedback", "command", "camera")  # what a paused lockstep simulator waits for (Clock)


@dataclass(kw_only=True, slots=True)
class Message:
    """Envelope fields common to all messages."""

    TYPE: ClassVar[str] = ""
    VERSION: ClassVar[int] = 1
    MAX_SIZE: ClassVar[int] = 1024 * 1024  # encoded bytes accepted on decode

    src: str = spec("", max_len=128)
    seq: int = spec(0, lo=0, hi=2**63 - 1)
    stamp: float = spec(0.0, lo=-TIME, hi=TIME)


# ---------------------------------------------------------------------------- nested records


@dataclass(kw_only=True, slots=True)
class PlanStep:
    """One action of a robot's plan, with its planned start and end on the site clock."""

    action: str = spec(choices=("approach", "opendoor", "gothrough", "load", "unload"))
    args: list[str] = spec(factory=list, max_len=8, ident=True)
    start: float = spec(lo=-TIME, hi=TIME)
    end: float = spec(lo=-TIME, hi=TIME)
    action_id: int = spec(0, lo=0, hi=2**31)


@dataclass(kw_only=True, slots=True)
class PlannedOpening:
    """A door opening the plan asks of the human: door ``door`` open during [start, end)."""

    door: str = spec(ident=True)
    start: float = spec(lo=-TIME, hi=TIME)
    end: float = spec(lo=-TIME, hi=TIME)
    robots: list[str] = spec(factory=list, max_len=1000, ident=True)


@dataclass(kw_only=True, slots=True)
class Constraint:
    """One active constraint: the library entry and its validated parameters, its window, its ASP."""

    id: str = spec(ident=True)
    kind: str = spec(ident=True)
    params: dict[str, Scalar] = spec(factory=dict, max_len=32)
    start: float = spec(lo=-TIME, hi=TIME)
    end: float = spec(lo=-TIME, hi=TIME)
    asp: str = spec(max_len=65536)
    origin: str = spec("", max_len=128)  # who asked for it (Feedback src)


@dataclass(kw_only=True, slots=True)
class Primitive:
    """A 2-D drawing instruction in image pixels, for thin clients."""

    kind: str = spec(choices=PRIMITIVE_KINDS)
    points: list[list[float]] = spec(factory=list, max_len=4096, row_len=2, lo=-1e6, hi=1e6)
    color: list[int] = spec(factory=lambda: [255, 255, 255, 255], max_len=4, lo=0, hi=255)
    width: float = spec(2.0, lo=0.0, hi=100.0)
    radius: float = spec(0.0, lo=0.0, hi=1e5)
    text: str = spec("", max_len=256)
    style: str = spec("solid", choices=LINE_STYLES)
    layer: str = spec("", max_len=64)  # e.g. robot id, "status", "door"


# ---------------------------------------------------------------------------- messages


@dataclass(kw_only=True, slots=True)
class Clock(Message):
    TYPE: ClassVar[str] = "Clock"
    time: float = spec(lo=0.0, hi=TIME)
    mode: str = spec("realtime", choices=("realtime", "rate", "lockstep", "wall"))
    rate: float = spec(1.0, lo=0.0, hi=1e6)
    world_version: int = spec(0, lo=0, hi=2**63 - 1)
    paused: bool = False
    # Lockstep, while paused: what the simulator waits for - "plan" (one answering world_version and
    # at least constraints_version), "feedback" (the ack of the human's feedback), "command" (a
    # robot's command of the plan it has), "camera" (the overlay of a frame it holds); "" otherwise.
    # The planner plans the moment the simulator waits for a plan, and holds while it waits for a
    # feedback's ack (a new constraint set follows).
    awaiting: str = spec("", choices=AWAITING)
    constraints_version: int = spec(0, lo=0, hi=2**63 - 1)


@dataclass(kw_only=True, slots=True)
class RobotPose(Message):
    TYPE: ClassVar[str] = "RobotPose"
    robot: str = spec(ident=True)
    x: float = spec(lo=-COORD, hi=COORD)
    y: float = spec(lo=-COORD, hi=COORD)
    theta: float = spec(lo=-ANGLE, hi=ANGLE)
    # "v" is the envelope's schema version, so the linear velocity travels as "vel".
    vel: float = spec(0.0, lo=-100.0, hi=100.0)
    omega: float = spec(0.0, lo=-100.0, hi=100.0)


@dataclass(kw_only=True, slots=True)
class RobotStatus(Message):
    TYPE: ClassVar[str] = "RobotStatus"
    robot: str = spec(ident=True)
    state: str = spec(choices=ROBOT_STATES)
    plan_id: int = spec(0, lo=0, hi=2**63 - 1)
    action_id: int = spec(0, lo=0, hi=2**31)  # 0: no action
    action: str = spec("", max_len=32)
    args: list[str] = spec(factory=list, max_len=8, ident=True)
    progress: float = spec(0.0, lo=0.0, hi=1.0)
    carrying: list[str] = spec(factory=list, max_len=1000, ident=True)
    delivered: list[str] = spec(factory=list, max_len=100_000, ident=True)
    waiting_door: str = spec("", max_len=64)
    detail: str = spec("", max_len=512)
    world_version: int = spec(0, lo=0, hi=2**63 - 1)


@dataclass(kw_only=True, slots=True)
class RobotCommand(Message):
    TYPE: ClassVar[str] = "RobotCommand"
    robot: str = spec(ident=True)
    plan_id: int = spec(lo=0, hi=2**63 - 1)
    action_id: int = spec(lo=0, hi=2**31)
    action: str = spec(choices=("approach", "opendoor", "gothrough", "load", "unload", "stop"))
    args: list[str] = spec(factory=list, max_len=8, ident=True)
    trajectory: list[list[float]] = spec(factory=list, max_len=MAX_TRAJECTORY, row_len=4, lo=-TIME, hi=TIME)
    duration: float = spec(0.0, lo=0.0, hi=1e6)  # for load/unload: time spent in place after the path


@dataclass(kw_only=True, slots=True)
class TeamPlan(Message):
    TYPE: ClassVar[str] = "TeamPlan"
    plan_id: int = spec(lo=0, hi=2**63 - 1)
    world_version: int = spec(0, lo=0, hi=2**63 - 1)
    constraints_version: int = spec(0, lo=0, hi=2**63 - 1)
    method: str = spec("iidp", max_len=32)
    makespan: float = spec(0.0, lo=0.0, hi=TIME)
    door_openings: int = spec(0, lo=0, hi=2**31)
    solve_time: float = spec(0.0, lo=0.0, hi=1e6)
    iterations: int = spec(0, lo=0, hi=2**31)
    robots: dict[str, list[PlanStep]] = spec(factory=dict, max_len=10_000)
    openings: list[PlannedOpening] = spec(factory=list, max_len=10_000)
    diagnostic: str = spec("", max_len=4096)


@dataclass(kw_only=True, slots=True)
class Intent(Message):
    TYPE: ClassVar[str] = "Intent"
    robot: str = spec(ident=True)
    plan_id: int = spec(0, lo=0, hi=2**63 - 1)
    action_id: int = spec(0, lo=0, hi=2**31)
    action: str = spec("", max_len=32)
    args: list[str] = spec(factory=list, max_len=8, ident=True)
    trajectory: list[list[float]] = spec(factory=list, max_len=MAX_TRAJECTORY, row_len=4, lo=-TIME, hi=TIME)


@dataclass(kw_only=True, slots=True)
class DoorState(Message):
    TYPE: ClassVar[str] = "DoorState"
    door: str = spec(ident=True)
    open: bool
    by: str = spec("", max_len=64)  # "human", a robot id, "sensor", or ""
    until: float = spec(0.0, lo=0.0, hi=TIME)  # when a human opening is due to end; 0 if unknown
    world_version: int = spec(0, lo=0, hi=2**63 - 1)


@dataclass(kw_only=True, slots=True)
class Feedback(Message):
    """A choice from the constraint library. ``params`` holds the entry's parameters, unchecked here:
    the restrictor validates them against the library and the site."""

    TYPE: ClassVar[str] = "Feedback"
    kind: str = spec(max_len=64)
    params: dict[str, Scalar] = spec(factory=dict, max_len=32)


@dataclass(kw_only=True, slots=True)
class FeedbackAck(Message):
    TYPE: ClassVar[str] = "FeedbackAck"
    to: str = spec(max_len=128)  # the Feedback's src
    feedback_seq: int = spec(lo=0, hi=2**63 - 1)
    accepted: bool
    reason: str = spec("", max_len=1024)
    constraint_id: str = spec("", max_len=64)
    constraints_version: int = spec(0, lo=0, hi=2**63 - 1)


@dataclass(kw_only=True, slots=True)
class ConstraintSet(Message):
    TYPE: ClassVar[str] = "ConstraintSet"
    version: int = spec(lo=0, hi=2**63 - 1)
    constraints: list[Constraint] = spec(factory=list, max_len=10_000)
    asp: str = spec("", max_len=1024 * 1024)  # all active constraints' ASP, ready for the solver


@dataclass(kw_only=True, slots=True)
class CameraFrame(Message):
    TYPE: ClassVar[str] = "CameraFrame"
    MAX_SIZE: ClassVar[int] = 16 * 1024 * 1024
    camera: str = spec(ident=True)
    jpeg: bytes = spec(max_len=16 * 1024 * 1024)
    width: int = spec(lo=1, hi=16384)
    height: int = spec(lo=1, hi=16384)
    intrinsics: list[float] = spec(max_len=4, lengths=(4,), lo=-1e6, hi=1e6)  # fx, fy, cx, cy
    distortion: list[float] = spec(
        factory=lambda: [0.0] * 5, max_len=5, lengths=(5,), lo=-1e6, hi=1e6
    )  # k1 k2 p1 p2 k3
    # The device's gravity at capture in the camera frame (OpenCV axes, pointing down, m/s²), as its
    # accelerometer measured it; empty when unknown. Optional: frames without it decode as before.
    gravity: list[float] = spec(factory=list, max_len=3, lengths=(0, 3), lo=-1000.0, hi=1000.0)


@dataclass(kw_only=True, slots=True)
class CameraTruth(Message):
    TYPE: ClassVar[str] = "CameraTruth"
    camera: str = spec(ident=True)
    frame_seq: int = spec(lo=0, hi=2**63 - 1)  # seq of the CameraFrame it belongs to
    position: list[float] = spec(max_len=3, lengths=(3,), lo=-COORD, hi=COORD)
    quaternion: list[float] = spec(max_len=4, lengths=(4,), lo=-1.0, hi=1.0)  # x, y, z, w of R_world_camera


@dataclass(kw_only=True, slots=True)
class Overlay(Message):
    TYPE: ClassVar[str] = "Overlay"
    camera: str = spec(ident=True)
    frame_seq: int = spec(0, lo=0, hi=2**63 - 1)
    width: int = spec(0, lo=0, hi=16384)
    height: int = spec(0, lo=0, hi=16384)
    ok: bool = False
    position: list[float] = spec(factory=list, max_len=3, lengths=(0, 3), lo=-COORD, hi=COORD)  # empty when not ok
    quaternion: list[float] = spec(factory=list, max_len=4, lengths=(0, 4), lo=-1.0, hi=1.0)
    tags: list[int] = spec(factory=list, max_len=1000, lo=0, hi=1_000_000)
    reprojection_rmse: float = spec(0.0, lo=0.0, hi=1e6)
    lost_age: float = spec(0.0, lo=0.0, hi=TIME)  # seconds since the last good pose when not ok
    latency: float = spec(0.0, lo=0.0, hi=1e6)
    primitives: list[Primitive] = spec(factory=list, max_len=20_000)


@dataclass(kw_only=True, slots=True)
class Event(Message):
    """Something that happened: ``door_opened``, ``delivered``, ``mission_done``, ``plan_conflict``, ...

    ``data`` carries kind-specific details (e.g. the metrics of ``mission_done``)."""

    TYPE: ClassVar[str] = "Event"
    kind: str = spec(ident=True)
    robot: str = spec("", max_len=64)
    door: str = spec("", max_len=64)
    object: str = spec("", max_len=64)
    data: Json = None


ALL_MESSAGES: tuple[type[Message], ...] = (
    Clock,
    RobotPose,
    RobotStatus,
    RobotCommand,
    TeamPlan,
    Intent,
    DoorState,
    Feedback,
    FeedbackAck,
    ConstraintSet,
    CameraFrame,
    CameraTruth,
    Overlay,
    Event,
)

BY_TYPE: dict[str, type[Message]] = {cls.TYPE: cls for cls in ALL_MESSAGES}
