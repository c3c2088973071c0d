"""What each kind of :class:`protocol.messages.Event` carries: one Struct per kind, in one registry.

An Event travels as ``{kind, robot, door, object, data}``; ``kind`` names the Struct its ``data``
is (:data:`EVENT_DATA`). The Event decodes ``data`` into that Struct as it is decoded or built
(:meth:`protocol.messages.Event.__post_init__`), so a reader reads fields (``event.data.pose``),
never keys, and a payload whose data does not fit its kind is refused naming the field.

Fields an emitter writes only sometimes are ``UNSET`` when absent: msgspec leaves them out of the
encoded data, so a map on the wire or in ``events.jsonl`` has exactly the keys it had when data
was a free map. ``stats`` (a service's counters, whose names each service chooses) is the one
kind whose data is a typed map rather than a Struct.
"""

from __future__ import annotations

from typing import Any, ClassVar

import msgspec
from msgspec import UNSET, Struct, UnsetType

from .errors import ProtocolError
from .schema import Float, Ident, Int, Json, List, Map, Rows, Scalar, Str, check_json, record_to_wire

SECONDS = Float(-1e10, 1e10)  # site-clock seconds (as the messages' TIME)
COUNT = Int(0, 2**63 - 1)
NUMBER = int | Float()  # a figure kept as written: an int stays an int in events.jsonl
POSE = List(Float(-1e6, 1e6), 3, lengths=(3,))  # [x, y, theta]
POSITION = List(Float(-1e6, 1e6), 2, lengths=(2,))  # [x, y]
TEXT = Str(4096)


class EventData(Struct, kw_only=True):
    """What one kind of event carries; ``KIND`` is the Event's ``kind`` for it."""

    KIND: ClassVar[str] = ""


# ---------------------------------------------------------------------------- the mission


class MissionStarted(EventData):
    KIND: ClassVar[str] = "mission_started"
    method: Str(64)
    seed: Int(-(2**63), 2**63 - 1)
    world_version: COUNT


class MissionDone(EventData):
    """The mission's metrics (``services/sim/metrics.py``); every field may be absent in a partial
    report (a test's, an aborted study trial's)."""

    KIND: ClassVar[str] = "mission_done"
    completed: bool | UnsetType = UNSET
    time: NUMBER | UnsetType = UNSET
    team_completion_time: NUMBER | None | UnsetType = UNSET
    agent_completion_times: Map(NUMBER | None) | UnsetType = UNSET
    human_door_openings: int | UnsetType = UNSET
    door_openings: Map(Map(int)) | UnsetType = UNSET  # door -> who opened it -> how often
    feedback: Map(int) | UnsetType = UNSET  # sent, accepted, refused, unanswered
    actions: Map(int) | UnsetType = UNSET  # done, failed
    closed_door_crossings: int | UnsetType = UNSET
    robot_overlaps: int | UnsetType = UNSET
    robot_overlaps_by_pair: Map(int) | UnsetType = UNSET
    robot_overlaps_by_place: Map(int) | UnsetType = UNSET
    wall_contacts: int | UnsetType = UNSET
    wall_contacts_by_place: Map(int) | UnsetType = UNSET
    wall_depth_max: NUMBER | UnsetType = UNSET
    world_versions: int | UnsetType = UNSET
    robots: Map(Map(Json)) | UnsetType = UNSET  # robot -> its figures (completion_time, wait_time ...)
    human: Map(Json) | UnsetType = UNSET  # her figures (door_openings, focus ...)
    params: Map(Json) | UnsetType = UNSET  # the engine's and the human model's settings
    reason: TEXT | UnsetType = UNSET  # why it ended unfinished (aborted)


class HumanDone(EventData):
    KIND: ClassVar[str] = "human_done"
    task_duration: NUMBER | None


# ---------------------------------------------------------------------------- robots' actions


class RobotOutcome(EventData):
    """Something a robot's action came to. The command's fields are absent when the robot had none;
    ``pose`` says where the robot was as it happened (a consumer can plan from it without waiting
    for the pose stream, which is not ordered with events); ``world_version`` is set when the
    planner must answer it."""

    plan_id: COUNT | UnsetType = UNSET
    action_id: COUNT | UnsetType = UNSET
    action: Str(32) | UnsetType = UNSET
    args: List(Ident, 8) | UnsetType = UNSET
    pose: POSE | UnsetType = UNSET
    reason: TEXT | UnsetType = UNSET
    world_version: COUNT | UnsetType = UNSET


class ActionDone(RobotOutcome):
    KIND: ClassVar[str] = "action_done"


class ActionFailed(RobotOutcome):
    KIND: ClassVar[str] = "action_failed"


class WaitingAtDoor(RobotOutcome):
    KIND: ClassVar[str] = "waiting_at_door"


class Loaded(RobotOutcome):
    KIND: ClassVar[str] = "loaded"


class Delivered(RobotOutcome):
    KIND: ClassVar[str] = "delivered"


# ---------------------------------------------------------------------------- doors and the human


class DoorChange(EventData):
    by: Str(64)  # "human", a robot id, "sensor"
    world_version: COUNT | UnsetType = UNSET  # a human-operated door's change is a new world
    until: SECONDS | UnsetType = UNSET  # when a human opening is due to end


class DoorOpened(DoorChange):
    KIND: ClassVar[str] = "door_opened"


class DoorClosed(DoorChange):
    KIND: ClassVar[str] = "door_closed"


class HumanOpensDoor(EventData):
    KIND: ClassVar[str] = "human_opens_door"
    opening: COUNT  # her openings so far
    by: Str(64) | UnsetType = UNSET  # who a door sensor says opened it


class FeedbackSent(EventData):
    KIND: ClassVar[str] = "feedback_sent"
    request: COUNT
    kind: Str(64)  # the constraint library entry
    params: Map(Scalar, 32) = {}


class FeedbackAnswered(EventData):
    KIND: ClassVar[str] = "feedback_answered"
    request: COUNT
    sent: SECONDS
    accepted: bool | None  # None: no answer came
    reason: TEXT = ""
    constraints_version: COUNT = 0


# ---------------------------------------------------------------------------- what should not happen


class ClosedDoorCrossing(EventData):
    KIND: ClassVar[str] = "closed_door_crossing"
    depth: NUMBER
    fraction: NUMBER
    pose: POSE


class RobotOverlap(EventData):
    KIND: ClassVar[str] = "robot_overlap"
    robots: List(Ident, 2)
    place: Str(64)
    depth: NUMBER
    poses: Rows(2, 2, -1e6, 1e6)  # each robot's [x, y]
    actions: List(Str(256), 2)  # what each was doing: says whether the plan or the execution let them meet


class WallContact(EventData):
    KIND: ClassVar[str] = "wall_contact"
    place: Str(64)
    depth: NUMBER
    pose: POSITION  # where the robot's centre was: [x, y]
    action: Str(256)


class PlanConflict(EventData):
    KIND: ClassVar[str] = "plan_conflict"
    constraints: List(Str(64), 10_000)  # the ids of a minimal set that cannot hold together
    constraints_version: COUNT
    reason: Str(1000)


# ---------------------------------------------------------------------------- the registry

STATS_KIND = "stats"
StatsData = Map(Str(128) | NUMBER)
"""A service's answer to a ``stats`` query: ``service``, ``instance`` and its counters and gauges by name."""

_STRUCTS: tuple[type[EventData], ...] = (
    MissionStarted,
    MissionDone,
    HumanDone,
    ActionDone,
    ActionFailed,
    WaitingAtDoor,
    Loaded,
    Delivered,
    DoorOpened,
    DoorClosed,
    HumanOpensDoor,
    FeedbackSent,
    FeedbackAnswered,
    ClosedDoorCrossing,
    RobotOverlap,
    WallContact,
    PlanConflict,
)
EVENT_DATA: dict[str, Any] = {**{cls.KIND: cls for cls in _STRUCTS}, STATS_KIND: StatsData}
"""Event kind -> the type of its data."""
EVENT_KINDS: tuple[str, ...] = tuple(EVENT_DATA)


def event_data(kind: str, data: Any) -> Any:
    """``data`` (a map as decoded, or None for none) as the type of ``kind``; :class:`ProtocolError`
    naming the field (``data.pose[2]``) when it does not fit."""
    from .validation import field_error  # late: validation reads the schema's markers

    target = EVENT_DATA.get(kind)
    if target is None:
        raise ProtocolError("kind", f"unknown event kind {kind[:64]!r} (one of {', '.join(EVENT_KINDS)})")
    raw = {} if data is None else data
    check_json(raw, "data")
    try:
        return msgspec.convert(raw, target)
    except msgspec.ValidationError as exc:
        raise field_error(exc, target, raw, prefix="data") from None


def data_to_wire(data: Any) -> Any:
    """An event's data as plain JSON-ready values (absent fields left out)."""
    return record_to_wire(data) if isinstance(data, Struct) else data
