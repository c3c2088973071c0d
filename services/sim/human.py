"""The simulated human (paper §V-A, DESIGN §6).

She has her own task (a0) of a total working time drawn once from a Gaussian. Robots that need her
door are helped by a1: she walks from her desk to the door, opens it, and walks back; the time she
is away is time not spent on her task, so every door she opens delays her. In ARROCH she can also
take a2(N), "I am unavailable for the next N minutes", which the simulator turns into a real
``door_unavailable`` Feedback to the restrictor.

When she decides to open the door depends on what she can see:

- with AR (``arroch`` and ``no-feedback``) she sees the robots waiting at her door. Each waiting
  robot is one independent chance per *decision interval*: when it starts waiting and then every
  ``decision_interval`` seconds while it still waits, she decides with ``door_probability``
  whether to go. More robots waiting, more chances: she is more likely to come.
- in ``no-comm`` she sees nothing: every ``no_comm_interval`` (a minute) she goes to open the door
  with ``no_comm_probability`` (0.6), whether a robot is there or not.

Focus intervals are drawn before she starts (their number and lengths from the config, placed
uniformly at random, not overlapping, within her nominal task time). At the start of each one, in
ARROCH only, she declares a2(N) with ``declare_probability`` (0.9), N being the interval's length in
whole minutes, for each door she operates; declaring takes ``declare_time`` (a tap). What a focus
interval does depends on the reading (``focus_reading``):

- ``faithful`` (the default, DESIGN §6 as corrected): a focus interval keeps her from opening doors
  only when she *declared* it. Then she draws no decision and a walk to the door turns back — the
  robots know and plan around her. Without the declaration (no-feedback, no-comm, and ARROCH's
  undeclared 10 %) she decides as at any other time: the robots she sees waiting call her away
  (no-comm: the once-a-minute rule goes on). Each time she leaves her task during a focus interval
  she loses ``interruption_cost`` seconds of it (resuming the puzzle): that interruption is what
  a2(N) exists to prevent.
- ``strict`` (the earlier reading, kept to compare): during any focus interval she opens no door,
  whatever the method; declaring changes nothing she does.

Three further parameters, each off by default so that the paper's model (and every sweep run
before them) is unchanged:

- ``focus_responsiveness`` (1 by default): during a focus interval she did not declare, each of her
  chances (per waiting robot and decision, or no-comm's per minute) is multiplied by it. 1 is the
  faithful reading above; 0 keeps her at her task through an undeclared interval as strict does
  (walks already under way go on). Between the two: how much an unannounced focus holds her back.
- ``anticipation`` (s, 0 = off): she uses what the AR view shows of the robots' *plans*. In the
  methods that show intentions (``arroch``, ``no-feedback``), a robot whose planned arrival at her
  door (``planned`` in :meth:`HumanModel.step`: the start of its next ``opendoor`` step there, from
  the plan the robots follow, see :func:`planned_arrivals`) is at most ``anticipation`` seconds
  ahead is one chance per decision interval, like a waiting robot, that she leaves for the door
  now, before it waits. In ``no-comm`` she sees no plan and never anticipates.
- ``focus_fraction`` (0 = off): her focus intervals take this share of her task time, split equally
  between ``focus_count`` intervals, so the share stays fixed when her task length changes. (Off,
  their lengths are whole minutes drawn from ``focus_min_minutes``..``focus_max_minutes``, and a
  short task holds fewer of them.) She declares a2(N) with N the whole minutes that cover the
  interval (the tablet takes whole minutes).

The model is pure: it reads the time, the robots waiting at her doors and whether each door is
open, and returns what she does. Every random number comes from a stream keyed by what it is for
(:mod:`.streams`): her task time, her focus intervals, the declaration at each interval, the k-th
decision about each robot at each door, the no-comm decision of each minute, the k-th anticipation
draw about each robot's planned arrival at each door (its own stream: an anticipation never moves
a draw the model made before it existed). So for one seed she
draws the same in every method and every condition, and methods are compared on the same draws.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Annotated, Any, Literal

from msgspec import Meta

from protocol.errors import ProtocolError
from protocol.validation import check_fields

from .streams import Streams

HUMAN_RADIUS = 0.18  # m, her torso: the camera's body and what a laser scan sees of her
METHODS = ("arroch", "no-feedback", "no-comm")
FOCUS_READINGS = ("faithful", "strict")  # see the module docstring


Probability = Annotated[float, Meta(ge=0.0, le=1.0)]
Positive = Annotated[float, Meta(gt=0.0)]
NonNegative = Annotated[float, Meta(ge=0.0)]
Count = Annotated[int, Meta(ge=0)]
Minutes = Annotated[int, Meta(ge=1)]
FocusShare = Annotated[float, Meta(ge=0.0, le=0.9)]  # at most 0.9: the intervals must fit in her task


@dataclass(frozen=True)
class HumanConfig:
    """The human model's parameters. Defaults: the paper's values where it gives them (0.6 per
    minute in no-comm, 0.9 for a2 at a focus interval's start); otherwise chosen to fit the
    office site (a delivery mission of a few robots takes 5–15 minutes). Each field's type states
    its limits, checked when a config is made (in code or from a file)."""

    task_mean: Positive = 600.0  # s of work her own task needs (Gaussian mean; chosen: the paper gives no figure)
    task_std: NonNegative = 60.0  # s (Gaussian standard deviation)
    task_min: NonNegative = 60.0  # s; the Gaussian is clipped here so a draw is never absurd
    walk_speed: Positive = 1.0  # m/s between her desk and a door
    open_time: NonNegative = 3.0  # s at the door to open it
    declare_time: NonNegative = 1.0  # s on the tablet to declare a2(N): one tap on a card (chosen)
    door_probability: Probability = 0.5  # chance per waiting robot per decision interval (AR methods)
    decision_interval: Positive = 10.0  # s between two decisions about one waiting robot
    no_comm_probability: Probability = 0.6  # chance per no_comm_interval (paper: 0.6 each minute)
    no_comm_interval: Positive = 60.0  # s
    focus_count: Count = 2  # focus intervals drawn before she finishes
    focus_min_minutes: Minutes = 2  # a focus interval lasts a whole number of minutes in [min, max]
    focus_max_minutes: Minutes = 4
    declare_probability: Probability = 0.9  # chance of a2(N) at a focus interval's start (paper: 0.9)
    # faithful: only a declared focus interval keeps her from doors; strict: any
    focus_reading: Literal[FOCUS_READINGS] = "faithful"  # type: ignore[valid-type]
    interruption_cost: NonNegative = (
        0.0  # s of her task lost each time she leaves it during a focus interval (chosen: 0)
    )
    feedback_timeout: Positive = 2.0  # s to wait for the restrictor's ack of one attempt (wall time)
    feedback_retries: Count = 3  # further attempts after the first goes unanswered
    # The three below are off by default (the module docstring): the paper's model is unchanged.
    # s ahead: a robot's planned arrival at her door this close is a chance to leave for it (AR methods; chosen)
    anticipation: NonNegative = 0.0
    # x her chances during an undeclared focus interval: 1 faithful (default), 0 she stays (chosen, swept)
    focus_responsiveness: Probability = 1.0
    focus_fraction: FocusShare = 0.0  # share of her task in focus intervals; 0: whole-minute lengths drawn

    def __post_init__(self) -> None:
        try:
            check_fields(type(self), asdict(self))
        except ProtocolError as exc:
            raise ValueError(f"human config: {exc}") from None
        if not self.focus_min_minutes <= self.focus_max_minutes:
            raise ValueError("human config: focus minutes need 1 <= focus_min_minutes <= focus_max_minutes")

    @classmethod
    def from_toml(cls, path: str | Path, **overrides: Any) -> HumanConfig:
        """Read ``[human]`` (or top-level keys) from a TOML file; ``overrides`` win over the file.

        Unknown keys are refused by name, so a typo never silently falls back to a default."""
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text())
        except FileNotFoundError:
            raise FileNotFoundError(f"human config {path} does not exist") from None
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"human config {path}: {exc}") from None
        try:
            values = check_fields(cls, data.get("human", data))
        except ProtocolError as exc:
            raise ValueError(f"human config {path}: {exc}") from None
        return replace(cls(**values), **{k: v for k, v in overrides.items() if v is not None})

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


# ---------------------------------------------------------------------------- what she does


@dataclass(frozen=True)
class OpenDoor:
    """She reached the door and opens it now."""

    door: str


@dataclass(frozen=True)
class Declare:
    """a2(N): she declares she will not open ``door`` for the next ``minutes`` minutes."""

    door: str
    minutes: int


@dataclass(frozen=True)
class TaskDone:
    """Her own task finished at ``time`` (within the step just taken)."""

    time: float


HumanAction = OpenDoor | Declare | TaskDone


@dataclass(frozen=True)
class FocusInterval:
    start: float
    end: float

    @property
    def minutes(self) -> int:
        """The whole minutes that cover the interval (a2(N) takes whole minutes); a whole-minute
        interval's own length (the tolerance absorbs the float error of ``end - start``)."""
        return max(1, math.ceil((self.end - self.start) / 60.0 - 1e-6))


@dataclass
class HumanCounters:
    """What she did, for the metrics and the statistics tests."""

    ar_decisions: int = 0  # draws made for a waiting robot
    ar_triggers: int = 0  # draws that sent her to the door
    no_comm_decisions: int = 0
    no_comm_triggers: int = 0
    door_trips: int = 0  # walks toward a door begun
    door_openings: int = 0  # times she opened a door (a1 completed)
    turned_back: int = 0  # walks abandoned because a focus interval she declared (strict: any) began
    anticipations: int = 0  # draws made for a robot's planned arrival (anticipation)
    anticipated: int = 0  # draws that sent her to the door before the robot waited there
    focus_started: int = 0
    declarations: int = 0  # a2(N) taken (one per focus interval, whatever the number of doors)
    interruptions: int = 0  # walks to a door begun during a focus interval (faithful reading)
    time_lost: float = 0.0  # s of her task lost to those interruptions (interruption_cost each)
    time_away: float = 0.0  # s spent walking and at the door
    time_declaring: float = 0.0


@dataclass
class _Trip:
    door: str
    leg: str  # "to", "at", "back"
    left: float  # s left on this leg
    walked: float = 0.0  # s walked toward the door so far (a turn-back returns the same way)


class HumanModel:
    """Her behaviour over time; call :meth:`step` once per engine tick."""

    def __init__(
        self,
        config: HumanConfig,
        method: str,
        streams: Streams,
        desk: tuple[float, float],
        doors: dict[str, tuple[float, float]],
    ) -> None:
        if method not in METHODS:
            raise ValueError(f"method {method!r} is not one of {', '.join(METHODS)}")
        self.config = config
        self.method = method
        self.streams = streams
        self.desk = desk
        self.door_points = dict(doors)  # where she stands to open each door she operates
        self.walk_time = {d: math.dist(desk, p) / config.walk_speed for d, p in doors.items()}
        # One standard normal per trial, scaled here: the same draw at every task length (the map's axis).
        z = float(streams.generator("task").standard_normal())
        self.task_duration = max(config.task_min, config.task_mean + config.task_std * z)
        self.focus = self._sample_focus(self.task_duration)
        self.declared = [self._would_declare(i) for i in range(len(self.focus))]
        self.counters = HumanCounters()
        self.work_done = 0.0
        self.done_time: float | None = None
        self.pause = 0.0  # s of declaring still to spend before work resumes
        self.trip: _Trip | None = None
        self._focus_next = 0  # index of the next focus interval to start
        self._next_check: dict[tuple[str, str], float] = {}  # (door, robot) -> next decision time
        self._draws: dict[tuple[str, str], int] = {}  # (door, robot) -> decisions drawn about it so far
        self._next_foresee: dict[tuple[str, str], float] = {}  # (door, robot) -> next anticipation decision time
        self._foreseen: dict[tuple[str, str], int] = {}  # (door, robot) -> anticipation draws so far
        self._minute = 0  # no-comm: index of the next once-a-minute decision
        self.opened_at: list[float] = []  # times she opened a door (for tests and metrics)

    # ------------------------------------------------------------------ set-up

    def _sample_focus(self, duration: float) -> list[FocusInterval]:
        """``focus_count`` non-overlapping intervals placed uniformly in [0, duration).

        Lengths first (whole minutes), then the free time is split by sorted uniform points: every
        placement of the intervals in order is equally likely. If they cannot fit, fewer are kept.
        """
        cfg = self.config
        rng = self.streams.generator("focus")
        if cfg.focus_fraction > 0:  # a fixed share of her task, in equal intervals (no length is drawn)
            lengths = [cfg.focus_fraction * duration / cfg.focus_count] * cfg.focus_count
        else:
            lengths = [
                60.0 * int(rng.integers(cfg.focus_min_minutes, cfg.focus_max_minutes + 1))
                for _ in range(cfg.focus_count)
            ]
        while lengths and sum(lengths) > 0.9 * duration:
            lengths.pop()
        free = duration - sum(lengths)
        cuts = sorted(float(u) * free for u in rng.random(size=len(lengths)))
        out, offset = [], 0.0
        for cut, length in zip(cuts, lengths, strict=True):
            start = cut + offset
            out.append(FocusInterval(start, start + length))
            offset += length
        return out

    def _would_declare(self, index: int) -> bool:
        """Whether she declares focus interval ``index`` (ARROCH only). The draw has a stream of its
        own (keyed by the interval), so drawing it or not moves no other draw of hers."""
        return (
            self.method == "arroch"
            and bool(self.door_points)
            and self.streams.uniform("declare", index) < self.config.declare_probability
        )

    # ------------------------------------------------------------------ queries

    def focus_at(self, t: float) -> int | None:
        """Index of the focus interval running at ``t``, if any."""
        for i, f in enumerate(self.focus):
            if f.start <= t < f.end:
                return i
        return None

    def in_focus(self, t: float) -> bool:
        return self.focus_at(t) is not None

    def unavailable(self, t: float) -> bool:
        """Whether a focus interval keeps her from her doors at ``t`` (see the module docstring)."""
        i = self.focus_at(t)
        if i is None or self.done:
            return False
        return self.config.focus_reading == "strict" or self.declared[i]

    @property
    def done(self) -> bool:
        return self.done_time is not None

    @property
    def available(self) -> bool:
        """At her desk (working, declaring, or finished): free to decide to go to a door."""
        return self.trip is None

    def pose(self) -> tuple[float, float, float]:
        """Where she is (x, y) and which way she faces, for rendering and the tablet camera."""
        if self.trip is None:
            door = next(iter(self.door_points.values()), None)
            yaw = math.atan2(door[1] - self.desk[1], door[0] - self.desk[0]) if door else 0.0
            return (*self.desk, yaw)
        target = self.door_points[self.trip.door]
        walk = self.walk_time[self.trip.door] or 1.0
        if self.trip.leg == "to":
            f = self.trip.walked / walk
            a, b = self.desk, target
        elif self.trip.leg == "at":
            f, a, b = 1.0, self.desk, target
        else:
            f = 1.0 - self.trip.left / walk
            a, b = target, self.desk
        f = min(max(f, 0.0), 1.0)
        return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), math.atan2(b[1] - a[1], b[0] - a[0]))

    # ------------------------------------------------------------------ behaviour

    def step(
        self,
        now: float,
        dt: float,
        waiting: dict[str, dict[str, float]],
        door_open: dict[str, bool],
        planned: Mapping[str, Mapping[str, float]] | None = None,
    ) -> list[HumanAction]:
        """Advance from ``now`` to ``now + dt``.

        ``waiting[door]`` maps each robot waiting at that door to the time it started waiting;
        ``door_open[door]`` says whether the door is open (or opening); ``planned[door]`` maps each
        robot the plan sends to that door to its planned arrival there (site clock, s;
        :func:`planned_arrivals`), what the AR view shows of the plans (used only with
        ``anticipation``). Decisions fall at the end of the step; walking and working are accounted
        exactly within it.
        """
        actions: list[HumanAction] = []
        t1 = now + dt
        self._advance(now, dt, actions)
        self._start_focus(t1, actions)
        draw = not self.unavailable(t1)  # a focus interval that keeps her away: decisions due meanwhile are skipped
        if self.method == "no-comm":
            self._decide_blind(t1, draw)
        else:
            self._decide_seen(t1, waiting, door_open, draw)
            if self.config.anticipation > 0 and planned:
                self._foresee(t1, planned, waiting, door_open, draw)
        # Forget robots no longer waiting, so a robot that comes back is seen afresh.
        live = {(d, r) for d, robots in waiting.items() for r in robots}
        for key in [k for k in self._next_check if k not in live]:
            del self._next_check[key]
        return actions

    def _chance(self, p: float, t: float) -> float:
        """``p`` as it stands at ``t``: scaled by ``focus_responsiveness`` in an undeclared focus
        interval (a declared one draws nothing at all). ``p * 1.0`` is ``p`` exactly, so the
        default changes no decision."""
        if self.done or self.focus_at(t) is None:
            return p
        return p * self.config.focus_responsiveness

    def _advance(self, now: float, dt: float, actions: list[HumanAction]) -> None:
        """Spend ``dt`` seconds on the current activity, moving on to the next when one ends."""
        t, left = now, dt
        while left > 1e-12:
            trip = self.trip
            if trip is None:
                spend = min(left, self.pause)
                self.pause -= spend
                self.counters.time_declaring += spend
                t, left = t + spend, left - spend
                if left <= 1e-12:
                    break
                if not self.done:
                    need = self.task_duration + self.counters.time_lost - self.work_done
                    if need <= left:
                        self.work_done += need
                        self.done_time = t + need
                        actions.append(TaskDone(self.done_time))
                    else:
                        self.work_done += left
                return
            spend = min(left, trip.left)
            trip.left -= spend
            self.counters.time_away += spend
            if trip.leg == "to":
                trip.walked += spend
            t, left = t + spend, left - spend
            if trip.left > 1e-12:
                return
            if trip.leg == "to":
                if self.unavailable(t):  # arrived as a focus interval that keeps her away runs: leave the door shut
                    self.counters.turned_back += 1
                    self.trip = _Trip(trip.door, "back", trip.walked)
                else:
                    actions.append(OpenDoor(trip.door))
                    self.counters.door_openings += 1
                    self.opened_at.append(t)
                    self.trip = _Trip(trip.door, "at", self.config.open_time)
            elif trip.leg == "at":
                self.trip = _Trip(trip.door, "back", self.walk_time[trip.door])
            else:
                self.trip = None

    def _start_focus(self, t1: float, actions: list[HumanAction]) -> None:
        while self._focus_next < len(self.focus) and self.focus[self._focus_next].start <= t1:
            index = self._focus_next
            interval = self.focus[index]
            self._focus_next += 1
            if self.done:
                continue  # intervals are part of her task: none once it is finished
            self.counters.focus_started += 1
            if self.declared[index]:
                self.counters.declarations += 1
                self.pause += self.config.declare_time
                for door in self.door_points:
                    actions.append(Declare(door, interval.minutes))
            if self.trip is not None and self.trip.leg == "to" and self.unavailable(t1):
                self.counters.turned_back += 1
                self.trip = _Trip(self.trip.door, "back", self.trip.walked)

    def _decide_seen(
        self, t1: float, waiting: dict[str, dict[str, float]], door_open: dict[str, bool], draw: bool
    ) -> None:
        for door in sorted(waiting):
            if door not in self.door_points:
                continue
            for robot in sorted(waiting[door]):
                key = (door, robot)
                due = self._next_check.get(key, waiting[door][robot])
                while due <= t1:
                    due += self.config.decision_interval
                    # A decision needs her at her desk and the door still shut.
                    if draw and self.available and not door_open.get(door, False):
                        k = self._draws.get(key, 0)
                        self._draws[key] = k + 1
                        self.counters.ar_decisions += 1
                        chance = self._chance(self.config.door_probability, t1)
                        if self.streams.uniform("seen", door, robot, k) < chance:
                            self.counters.ar_triggers += 1
                            self._go(door, t1)
                self._next_check[key] = due

    def _decide_blind(self, t1: float, draw: bool) -> None:
        while (self._minute + 1) * self.config.no_comm_interval <= t1:
            self._minute += 1
            if draw and self.available and self.door_points:
                self.counters.no_comm_decisions += 1
                if self.streams.uniform("blind", self._minute) < self._chance(self.config.no_comm_probability, t1):
                    self.counters.no_comm_triggers += 1
                    doors = sorted(self.door_points)
                    door = doors[int(self.streams.uniform("blind-door", self._minute) * len(doors))]
                    self._go(door, t1)

    def _foresee(
        self,
        t1: float,
        planned: Mapping[str, Mapping[str, float]],
        waiting: dict[str, dict[str, float]],
        door_open: dict[str, bool],
        draw: bool,
    ) -> None:
        """Anticipation: each robot whose planned arrival at her door is within the horizon, and that
        does not wait there yet, is one chance per decision interval that she leaves now."""
        horizon = self.config.anticipation
        seen: set[tuple[str, str]] = set()
        for door in sorted(planned):
            if door not in self.door_points:
                continue
            for robot in sorted(planned[door]):
                arrival = planned[door][robot]
                if robot in waiting.get(door, {}) or not 0.0 <= arrival - t1 <= horizon:
                    continue
                key = (door, robot)
                seen.add(key)
                due = self._next_foresee.get(key, max(arrival - horizon, 0.0))
                while due <= t1:
                    due += self.config.decision_interval
                    if draw and self.available and not door_open.get(door, False):
                        k = self._foreseen.get(key, 0)
                        self._foreseen[key] = k + 1
                        self.counters.anticipations += 1
                        if self.streams.uniform("anticipate", door, robot, k) < self._chance(
                            self.config.door_probability, t1
                        ):
                            self.counters.anticipated += 1
                            self._go(door, t1)
                self._next_foresee[key] = due
        # A robot out of her horizon (arrived, replanned, gone) is foreseen afresh next time.
        for key in [k for k in self._next_foresee if k not in seen]:
            del self._next_foresee[key]

    def _go(self, door: str, t: float) -> None:
        self.counters.door_trips += 1
        if self.in_focus(t) and not self.done:
            # She leaves her task in the middle of a focus interval: resuming it costs her.
            self.counters.interruptions += 1
            self.counters.time_lost += self.config.interruption_cost
        self.trip = _Trip(door, "to", self.walk_time[door])

    def focus_report(self) -> list[dict[str, Any]]:
        return [
            {"start": f.start, "end": f.end, "minutes": f.minutes, "declared": declared}
            for f, declared in zip(self.focus, self.declared, strict=True)
        ]


def planned_arrivals(plans: Mapping[str, Sequence[Any]], doors: Iterable[str]) -> dict[str, dict[str, float]]:
    """What the AR view shows her of the plans: per door of hers, each robot's planned arrival there.

    ``plans`` maps each robot to its plan's steps (a TeamPlan's ``robots``: steps with ``action``,
    ``args`` and ``start`` on the site clock); a robot's arrival at a door is the start of its first
    ``opendoor`` step at that door (where the plan has it wait for her)."""
    wanted = set(doors)
    out: dict[str, dict[str, float]] = {d: {} for d in sorted(wanted)}
    for robot, steps in sorted(plans.items()):
        for step in steps:
            if step.action == "opendoor" and step.args and step.args[0] in wanted:
                out[step.args[0]].setdefault(robot, float(step.start))
    return out
