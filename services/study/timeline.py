"""One trial's ``log.jsonl`` read as what happened over time: her trips to the door, the views she
looked at, her puzzle moves, her feedback, the robots waiting at her door and the door's state.

Rules (what the report and the calibration both rely on):

- **start** of the trial: Event ``mission_started`` (else the first record); **end**: Event
  ``mission_done`` (else the last record); **task done**: her ``task_done`` act (else Event ``human_done``).
- **a trip** away from her desk begins with ``go_to_door`` (or a HumanState whose place is not
  ``desk``) and ends with the next HumanState at ``desk``. A log without any HumanState (a world
  that does not publish her place) ends a trip at her first puzzle move, view change or task done
  after she opened the door or turned back: she is evidently back at the tablet.
- **a view away**: from a ``view`` act showing ``ar`` or ``map`` to the next one showing ``puzzle``;
  the page starts on the puzzle.
- **away from the puzzle**: on a trip or in a view away (their union).
- **the door is open** (or opening) from her ``open_door`` act, a DoorState ``open`` or Event
  ``door_opened``, until DoorState not ``open`` or Event ``door_closed``.
- **a declaration** (a2(N)) is a ``feedback`` act of kind ``door_unavailable``; acts inside one view
  away (or, outside any, less than ``GROUP_GAP`` s apart) are one declaration (one per door she
  operates, as the simulated human sends them).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .layout import StudyError, read_jsonl

DECLARE_KIND = "door_unavailable"  # the library entry of a2(N)
AVAILABLE_KIND = "door_available_now"  # ends a declared window early on the same door
GROUP_GAP = 5.0  # s: feedback acts closer than this outside a view away are one declaration


@dataclass(frozen=True)
class Span:
    start: float
    end: float

    @property
    def length(self) -> float:
        return max(0.0, self.end - self.start)


@dataclass(frozen=True)
class Trip:
    start: float
    end: float
    door: str
    opened: bool


@dataclass(frozen=True)
class Move:
    t: float
    piece: int
    correct: bool
    placed: int
    total: int


@dataclass(frozen=True)
class FeedbackAct:
    t: float
    door: str
    minutes: int
    kind: str


@dataclass(frozen=True)
class RobotEvent:
    t: float
    kind: str
    robot: str
    door: str


@dataclass
class Timeline:
    source: str
    start: float
    end: float
    task_done: float | None
    trips: list[Trip] = field(default_factory=list)
    views_away: list[Span] = field(default_factory=list)
    moves: list[Move] = field(default_factory=list)
    feedback: list[FeedbackAct] = field(default_factory=list)
    events: list[RobotEvent] = field(default_factory=list)  # Events naming a robot or a door, in order
    door_open: dict[str, list[Span]] = field(default_factory=dict)
    doors: list[str] = field(default_factory=list)  # the doors she operates (HumanState.doors, else seen)
    goes: list[tuple[float, str]] = field(default_factory=list)  # (time, door) of each go_to_door

    @property
    def work_end(self) -> float:
        """When her own task ended (task done, else the end of the trial)."""
        return self.task_done if self.task_done is not None else self.end

    def away(self, lo: float | None = None, hi: float | None = None) -> list[Span]:
        """The spans away from the puzzle (trips and views away, merged), clipped to [lo, hi]."""
        lo = self.start if lo is None else lo
        hi = self.work_end if hi is None else hi
        spans = [Span(t.start, t.end) for t in self.trips] + list(self.views_away)
        return clip(union(spans), lo, hi)

    def time_away(self) -> float:
        """Seconds away from the puzzle between the start and her task done (or the end)."""
        return sum(s.length for s in self.away())

    def active_time(self) -> float:
        """Seconds at her desk in the puzzle view between the start and her task done (or the end)."""
        return max(0.0, self.work_end - self.start) - self.time_away()

    def declarations(self) -> list[list[FeedbackAct]]:
        """Her a2(N) declarations, each the feedback acts it consists of (module docstring)."""
        groups: list[list[FeedbackAct]] = []
        last_span: Span | None = None
        for act in self.feedback:
            if act.kind != DECLARE_KIND:
                continue
            span = next((s for s in self.views_away if s.start <= act.t <= s.end), None)
            if not groups:
                same = False
            elif span is not None:
                same = span == last_span
            else:
                same = last_span is None and act.t - groups[-1][-1].t < GROUP_GAP
            if same:
                groups[-1].append(act)
            else:
                groups.append([act])
            last_span = span
        return groups

    def declaration_times(self) -> list[float]:
        """Durations of the views away that contain a declaration and overlap no trip."""
        out = []
        for span in self.views_away:
            has_declaration = any(span.start <= a.t <= span.end and a.kind == DECLARE_KIND for a in self.feedback)
            crosses_trip = any(t.start < span.end and t.end > span.start for t in self.trips)
            if has_declaration and not crosses_trip:
                out.append(span.length)
        return out

    def is_open(self, door: str, t: float) -> bool:
        return any(s.start <= t < s.end for s in self.door_open.get(door, []))


# ---------------------------------------------------------------------------- intervals


def union(spans: Iterable[Span]) -> list[Span]:
    """Overlapping or touching spans merged, in order."""
    out: list[Span] = []
    for s in sorted(spans, key=lambda s: (s.start, s.end)):
        if out and s.start <= out[-1].end:
            out[-1] = Span(out[-1].start, max(out[-1].end, s.end))
        else:
            out.append(s)
    return out


def clip(spans: Iterable[Span], lo: float, hi: float) -> list[Span]:
    return [Span(max(s.start, lo), min(s.end, hi)) for s in spans if s.end > lo and s.start < hi]


def overlap(spans: Iterable[Span], lo: float, hi: float) -> float:
    """Total length of ``spans`` (disjoint) inside [lo, hi]."""
    return sum(s.length for s in clip(spans, lo, hi))


# ---------------------------------------------------------------------------- reading


def read_log(path: Path) -> list[dict[str, Any]]:
    """The log's records, checked (an object with a finite numeric ``t`` and a ``type``), in time order."""
    records = []
    for number, rec in enumerate(read_jsonl(path), 1):
        if not isinstance(rec, dict):
            raise StudyError(f"{path}: record {number} is not a JSON object")
        t = rec.get("t")
        if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t):
            raise StudyError(f"{path}: record {number} has no numeric 't' (site seconds): {str(rec)[:120]}")
        if not isinstance(rec.get("type"), str):
            raise StudyError(f"{path}: record {number} has no message 'type': {str(rec)[:120]}")
        records.append(rec)
    # Records are written in the order heard; stamps from different senders may interleave slightly.
    return sorted(records, key=lambda r: float(r["t"]))


def _field(rec: dict[str, Any], name: str, kind: type, default: Any, where: str) -> Any:
    value = rec.get(name, default)
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise StudyError(f"{where}: field {name!r} should be {kind.__name__}, not {value!r}")
    return value


def build_timeline(records: list[dict[str, Any]], source: str) -> Timeline:
    """The timeline of one trial from its (checked, time-ordered) log records."""
    if not records:
        raise StudyError(f"{source}: the log is empty")
    started = [r["t"] for r in records if r["type"] == "Event" and r.get("kind") == "mission_started"]
    finished = [r["t"] for r in records if r["type"] == "Event" and r.get("kind") == "mission_done"]
    tl = Timeline(
        source=source,
        start=float(started[0]) if started else float(records[0]["t"]),
        end=float(finished[0]) if finished else float(records[-1]["t"]),
        task_done=None,
    )
    has_place = any(r["type"] == "HumanState" for r in records)
    doors_seen: list[str] = []
    trip: dict[str, Any] | None = None  # the open trip: start, door, opened, returning
    view = "puzzle"
    view_left = 0.0
    open_since: dict[str, float] = {}

    def close_trip(t: float) -> None:
        nonlocal trip
        if trip is not None:
            tl.trips.append(Trip(trip["start"], max(t, trip["start"]), trip["door"], trip["opened"]))
            trip = None

    def door_opens(door: str, t: float) -> None:
        if door and door not in open_since:
            open_since[door] = t

    def door_closes(door: str, t: float) -> None:
        if door in open_since:
            tl.door_open.setdefault(door, []).append(Span(open_since.pop(door), t))

    for number, rec in enumerate(records, 1):
        t = float(rec["t"])
        kind = rec["type"]
        where = f"{source}: record {number} (t={t:g})"
        if kind == "ParticipantAction":
            act = _field(rec, "act", str, "", where)
            door = _field(rec, "door", str, "", where)
            if not has_place and trip is not None and trip["returning"] and act in ("puzzle_move", "view", "task_done"):
                close_trip(t)
            if act == "go_to_door":
                tl.goes.append((t, door))
                if trip is None:
                    trip = {"start": t, "door": door, "opened": False, "returning": False}
                if door and door not in doors_seen:
                    doors_seen.append(door)
            elif act == "open_door":
                door_opens(door, t)
                if trip is not None:
                    trip["opened"] = True
                    trip["returning"] = True
            elif act == "back_to_desk":
                if trip is not None:
                    trip["returning"] = True
            elif act == "view":
                shown = _field(rec, "view", str, "", where)
                if shown == "puzzle" and view != "puzzle":
                    tl.views_away.append(Span(view_left, t))
                elif shown in ("ar", "map") and view == "puzzle":
                    view_left = t
                view = shown or view
            elif act == "puzzle_move":
                tl.moves.append(
                    Move(
                        t,
                        _field(rec, "piece", int, -1, where),
                        _field(rec, "correct", bool, False, where),
                        _field(rec, "placed", int, 0, where),
                        _field(rec, "total", int, 0, where),
                    )
                )
            elif act == "feedback":
                note = _field(rec, "note", str, "", where)
                minutes = _field(rec, "minutes", int, 0, where)
                tl.feedback.append(FeedbackAct(t, door, minutes, note))
            elif act == "task_done" and tl.task_done is None:
                tl.task_done = t
        elif kind == "HumanState":
            place = _field(rec, "place", str, "desk", where)
            for door in _field(rec, "doors", list, [], where):
                if isinstance(door, str) and door not in tl.doors:
                    tl.doors.append(door)
            if place == "desk":
                close_trip(t)
            elif trip is None:
                trip = {"start": t, "door": _field(rec, "door", str, "", where), "opened": False, "returning": False}
        elif kind == "DoorState":
            door = _field(rec, "door", str, "", where)
            if _field(rec, "open", bool, False, where):
                door_opens(door, t)
            else:
                door_closes(door, t)
        elif kind == "Event":
            ev = _field(rec, "kind", str, "", where)
            door = _field(rec, "door", str, "", where)
            robot = _field(rec, "robot", str, "", where)
            if ev == "door_opened":
                door_opens(door, t)
            elif ev == "door_closed":
                door_closes(door, t)
            elif ev == "human_done" and tl.task_done is None:
                tl.task_done = t
            if ev == "waiting_at_door" and door and door not in doors_seen:
                doors_seen.append(door)
            if robot or door:
                tl.events.append(RobotEvent(t, ev, robot, door))
    close_trip(tl.end)
    if view != "puzzle":
        tl.views_away.append(Span(view_left, max(view_left, tl.end)))
    for door in list(open_since):
        door_closes(door, max(open_since[door], tl.end))
    if not tl.doors:
        tl.doors = doors_seen
    return tl


def load_timeline(path: Path) -> Timeline:
    return build_timeline(read_log(path), str(path))
