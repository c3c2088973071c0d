"""The simulation's tick loop: time, robots, doors and the human, and what comes of them.

One :meth:`Engine.step` advances sim time by ``tick`` seconds (20 Hz by default): robots first (in
id order), then doors (they see this tick's requests and the robots' new positions), then the
human (she sees who waits now). Stepping is kinematic and needs no physics engine; the pybullet
scene only mirrors the result when something looks at it (see :mod:`services.sim.mirror`).

Everything the outside world must hear comes out of :meth:`take_events` (in order) and the
``status_changed``/door change flags; feedback the human gives comes out of
:meth:`take_feedback`. The engine never reads a clock or the network: given the site, the seed and
the same commands at the same ticks, it produces the same events.

``world_version`` counts the states the planner must answer (docs/services/sim.md): the mission
start, every action done or failed (except a ``stop``), every opening or closing of a
human-operated door. Automatic doors open and close for robots without a new version: they never
block a plan, and a version per automatic door swing would only make the planner replan for nothing.

The human is the simulated one (:class:`~.human.HumanModel`) or, with ``human="participant"``, a
person on her tablet page (:class:`~.participant.ParticipantHuman`), whose acts come in through
:meth:`Engine.human_act`. With ``door_sensors`` the human-operated doors are real ones and follow
their sensors (:meth:`Engine.door_sensor`); a participant then opens them herself, and those
openings count as hers. :meth:`Engine.abort` ends the mission at once, not completed.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from protocol.events import (
    ActionFailed,
    ClosedDoorCrossing,
    DoorClosed,
    DoorOpened,
    EventData,
    FeedbackAnswered,
    FeedbackSent,
    HumanDone,
    HumanOpensDoor,
    MissionDone,
    MissionStarted,
    RobotOverlap,
    WallContact,
    data_to_wire,
)
from protocol.messages import RobotCommand, TeamPlan
from protocol.site.model import Site
from runtime.executor import Outcome, Robot, RobotConfig, RobotExecutor
from runtime.pursuit import ControllerConfig

from .crossings import ClosedDoorWatch
from .doors import DoorChange, DoorConfig, Doors
from .human import Declare, HumanConfig, HumanModel, OpenDoor, TaskDone, planned_arrivals
from .metrics import MetricsRecorder
from .objects import Objects
from .overlaps import OverlapWatch
from .participant import HUMAN_MODES, ParticipantHuman, Refused
from .streams import Streams
from .walls import WallWatch

HUMAN_DOOR_STANDOFF = 0.5  # m in front of a door where the human stands to open it


@dataclass(frozen=True)
class EngineConfig:
    tick: float = 0.05  # s of sim time per step
    time_limit: float = 7200.0  # s of sim time after which the mission ends unfinished (0: never)
    max_turn_rate: float = 1.5  # rad/s
    lookahead: float = 0.3  # m, pure pursuit
    door_swing_time: float = 1.5  # s
    auto_close_delay: float = 1.0  # s
    stop_margin: float = 0.15  # m
    auto_open_distance: float = 1.5  # m
    start_tolerance: float = 1.5  # m
    reach: float = 1.0  # m

    def __post_init__(self) -> None:
        if not self.tick > 0 or self.time_limit < 0:
            raise ValueError("engine config: tick must be > 0 and time_limit >= 0")

    def as_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class SimEvent:
    time: float
    data: EventData  # its type says the kind (protocol.events)
    robot: str = ""
    door: str = ""
    object: str = ""

    @property
    def kind(self) -> str:
        return self.data.KIND

    def as_dict(self) -> dict[str, Any]:
        """The line of ``events.jsonl``: the Event's fields and ``time``."""
        return {
            "time": self.time,
            "kind": self.kind,
            "robot": self.robot,
            "door": self.door,
            "object": self.object,
            "data": data_to_wire(self.data),
        }


@dataclass(frozen=True)
class FeedbackRequest:
    """Feedback the human gives; the service sends it and reports the answer back."""

    id: int
    time: float
    kind: str
    params: dict[str, Any]


class Engine:
    def __init__(
        self,
        site: Site,
        *,
        method: str,
        seed: int,
        human: HumanConfig | None = None,
        config: EngineConfig | None = None,
        human_mode: str = "simulated",
        door_sensors: bool = False,
    ) -> None:
        if human_mode not in HUMAN_MODES:
            raise ValueError(f"human mode {human_mode!r} is not one of {', '.join(HUMAN_MODES)}")
        if door_sensors and human_mode != "participant":
            # A real door is opened by a real hand: the simulated human cannot open it.
            raise ValueError("door sensors (real doors) go with a participant, not the simulated human")
        self.site = site
        self.method = method
        self.seed = seed
        self.config = config or EngineConfig()
        self.human_config = human or HumanConfig()
        p = site.params
        self.streams = Streams(seed)  # the run's only source of randomness, keyed by purpose (streams.py)
        self.doors = Doors(
            site.doors.values(),
            DoorConfig(
                swing_time=self.config.door_swing_time,
                hold_time=p.door_hold_time,
                auto_close_delay=self.config.auto_close_delay,
            ),
            p.robot_radius,
            site.door_leaves,
        )
        self.objects = Objects(site.objects)
        controller = ControllerConfig(
            speed=p.robot_speed, max_turn_rate=self.config.max_turn_rate, lookahead=self.config.lookahead
        )
        self.executor = RobotExecutor(
            site,
            self.doors,
            self.objects,
            RobotConfig(
                controller=controller,
                radius=p.robot_radius,
                load_time=p.load_time,
                capacity=p.robot_capacity,
                stop_margin=self.config.stop_margin,
                auto_open_distance=self.config.auto_open_distance,
                start_tolerance=self.config.start_tolerance,
                reach=self.config.reach,
            ),
        )
        self.robots: dict[str, Robot] = {rid: Robot(rid, *spec.start) for rid, spec in sorted(site.robots.items())}
        self.executor.fleet = self.robots
        # Robots executed elsewhere (services/sim/ros2_base.py): stepped by their own object, not the executor.
        self.external: dict[str, Any] = {}
        self.closed_doors = ClosedDoorWatch(self.doors, p.robot_radius)  # safety invariant, checked every tick
        self.overlaps = OverlapWatch(site, p.robot_radius)  # robot-robot contact, checked every tick
        self.wall_contacts = WallWatch(site, p.robot_radius)  # robot-wall contact, checked every tick
        her_room = site.human.room
        self.human_doors = sorted(d.id for d in site.doors.values() if d.human_operated and her_room in d.rooms)
        door_points = {d: site.doors[d].beside(her_room, HUMAN_DOOR_STANDOFF) for d in self.human_doors}
        self.participant = human_mode == "participant"
        self.door_sensors = door_sensors
        self.human: HumanModel | ParticipantHuman
        if self.participant:
            self.human = ParticipantHuman(self.human_config, site.human.position, door_points, sensor=door_sensors)
        else:
            self.human = HumanModel(self.human_config, method, self.streams, site.human.position, door_points)
        if door_sensors:
            self.doors.follow_sensors(d.id for d in site.doors.values() if d.human_operated)
        # Per door of hers, each robot's planned arrival in the plan the robots follow (what the AR view shows her).
        self.planned: dict[str, dict[str, float]] = {}
        self.ticks = 0
        self.world_version = 0
        self.done = False
        self.completed = False
        self.door_changed: set[str] = set(self.doors.doors)  # doors whose state must be published
        self.door_by: dict[str, str] = {}  # who opened each door last
        self._events: list[SimEvent] = []
        self._feedback: list[FeedbackRequest] = []
        self._feedback_ids = 0
        self._waiting_since: dict[str, tuple[str, float]] = {}  # robot -> (door, since)
        self.end_reason = ""  # why the mission ended early (an abort)
        self.metrics = MetricsRecorder(
            params={
                "site": site.name,
                "method": method,
                "seed": seed,
                "human": self.human_config.as_dict(),
                "engine": self.config.as_dict(),
                "robot_motion": self.executor.motion_params(),
                "site_params": {k: getattr(p, k) for k in p.__dataclass_fields__},
                "robots": len(self.robots),
                "objects": len(self.objects.items),
                "human_doors": self.human_doors,
                "human_mode": human_mode,
                "doors": "sensor" if door_sensors else "sim",
            }
        )

    # ------------------------------------------------------------------ time

    @property
    def time(self) -> float:
        # From the tick count, not a running sum: no float drift, identical across runs.
        # Rounded so that logs read 19.4, not 19.400000000000002.
        return round(self.ticks * self.config.tick, 9)

    def start(self) -> None:
        """The mission starts: the first state the planner must answer."""
        self._new_world()
        self._emit(MissionStarted(method=self.method, seed=self.seed, world_version=self.world_version))

    def step(self) -> None:
        """Advance one tick."""
        if self.done:
            return
        now, dt = self.time, self.config.tick
        for robot in self.robots.values():
            self._report(self.external.get(robot.id, self.executor).step(robot, now, dt), now + dt)
        positions = [(r.x, r.y) for r in self.robots.values()]
        self.ticks += 1
        t1 = self.time
        for change in self.doors.step(now, dt, positions):
            self._door_change(change, t1)
        for crossing in self.closed_doors.check(self.robots.values()):
            self.metrics.closed_door_crossings += 1
            self._emit(
                ClosedDoorCrossing(depth=crossing.depth, fraction=crossing.fraction, pose=list(crossing.pose)),
                robot=crossing.robot,
                door=crossing.door,
            )
        for overlap in self.overlaps.check(self.robots.values()):
            self.metrics.overlap(overlap.robots, overlap.place)
            self._emit(
                RobotOverlap(
                    robots=list(overlap.robots),
                    place=overlap.place,
                    depth=overlap.depth,
                    poses=[list(p) for p in overlap.poses],
                    actions=[self._doing(rid) for rid in overlap.robots],
                ),
                robot=overlap.robots[0],
            )
        for contact in self.wall_contacts.check(self.robots.values()):
            self.metrics.wall_contact(contact.place)
            self._emit(
                WallContact(
                    place=contact.place,
                    depth=contact.depth,
                    pose=list(contact.pose),
                    action=self._doing(contact.robot),
                ),
                robot=contact.robot,
            )
        self._track_waiting(t1)
        waiting: dict[str, dict[str, float]] = {d: {} for d in self.human_doors}
        for rid, (door, since) in self._waiting_since.items():
            if door in waiting:
                waiting[door][rid] = since
        door_open = {d: self.doors[d].open_or_opening for d in self.human_doors}
        for action in self.human.step(now, dt, waiting, door_open, planned=self.planned):
            self._human_action(action, t1)
        self._check_end(t1)

    # ------------------------------------------------------------------ inputs

    def apply_command(self, cmd: RobotCommand) -> str:
        """Apply a command now. Returns ``"applied"``, ``"stale"`` (not newer than the last one for
        that robot), ``"external"`` (a robot its own driver executes) or ``"unknown_robot"``."""
        robot = self.robots.get(cmd.robot)
        if robot is None:
            self._emit(
                ActionFailed(
                    plan_id=cmd.plan_id,
                    action_id=cmd.action_id,
                    action=cmd.action,
                    args=list(cmd.args),
                    reason=f"no robot {cmd.robot!r} on this site",
                ),
                robot=cmd.robot,
            )
            return "unknown_robot"
        if robot.id in self.external:
            self.external[robot.id].command(cmd)
            return "external"
        if cmd.action_id <= robot.last_action_id:
            return "stale"
        self._waiting_since.pop(robot.id, None)
        self._report(self.executor.assign(robot, cmd), self.time)
        return "applied"

    def human_act(self, act: str, door: str = "") -> str:
        """A participant's act (``go_to_door``, ``open_door``, ``back_to_desk``, ``task_done``), taken
        now. Returns ``""``, or why it was refused (naming the field at fault); never raises."""
        if not isinstance(self.human, ParticipantHuman):
            return "act: the simulated human plays her part here (arroch sim --human participant takes acts)"
        if self.done:
            return f"act: the mission is over (t={self.time:.2f})"
        t = self.time
        try:
            actions = self.human.act(act, door, t)
        except Refused as exc:
            return str(exc)
        for action in actions:
            self._human_action(action, t)
        self._check_end(t)
        return ""

    def door_sensor(self, door: str, is_open: bool, by: str = "") -> str:
        """A real door's sensor says it is open or shut (``by``: who opened it, "sensor" if nobody
        says). Returns ``""``, or why the report was refused (naming the field); never raises."""
        if door not in self.doors:
            return f"door: no door {door!r} on site {self.site.name}"
        if not self.doors[door].sensor:
            kind = "human-operated, but the doors are simulated" if self.doors[door].human_operated else "automatic"
            return f"door: {door!r} follows no sensor ({kind})"
        if self.done:
            return f"open: the mission is over (t={self.time:.2f})"
        by = by or "sensor"
        if self.doors.sensor_says(door, is_open, by):
            self.door_changed.add(door)
            if isinstance(self.human, ParticipantHuman) and door in self.human_doors:
                self.human.sensor_opening(door, self.time)  # a real door of hers opened: her opening
            self._emit(HumanOpensDoor(opening=self.human.counters.door_openings, by=by), door=door)
        return ""

    def abort(self, reason: str) -> None:
        """End the mission now, not completed (the experimenter aborted the trial)."""
        if self.done:
            return
        self.done = True
        self.completed = False
        self.end_reason = reason
        self._emit(MissionDone(**self.summary()))

    def feedback_answered(
        self, request: FeedbackRequest, *, accepted: bool | None, reason: str = "", constraints_version: int = 0
    ) -> None:
        """The restrictor's answer to the human's feedback (``accepted=None``: none came)."""
        self.metrics.feedback_answer(accepted)
        self._emit(
            FeedbackAnswered(
                request=request.id,
                sent=request.time,
                accepted=accepted,
                reason=reason,
                constraints_version=constraints_version,
            ),
            door=str(request.params.get("door", "")),
        )

    # ------------------------------------------------------------------ outputs

    def plan_seen(self, plan: TeamPlan) -> None:
        """The plan the robots now follow: the human model reads their planned arrivals at her doors."""
        self.planned = planned_arrivals(plan.robots, self.human_doors)

    def take_events(self) -> list[SimEvent]:
        events, self._events = self._events, []
        return events

    def take_feedback(self) -> list[FeedbackRequest]:
        out, self._feedback = self._feedback, []
        return out

    def human_pose(self) -> tuple[float, float, float]:
        return self.human.pose()

    def human_place(self) -> tuple[str, str]:
        """Where the human is (``HumanState.place``: desk, to_door, at_door, back) and the door of her walk."""
        h = self.human
        if isinstance(h, ParticipantHuman):
            return h.place, h.door
        if h.trip is None:
            return "desk", ""
        return {"to": "to_door", "at": "at_door", "back": "back"}[h.trip.leg], h.trip.door

    # ------------------------------------------------------------------ internals

    def _doing(self, rid: str) -> str:
        robot = self.robots[rid]
        cmd = robot.command
        action = f"{cmd.action}({','.join(cmd.args)})#{cmd.action_id}" if cmd is not None else "-"
        return f"{action} {robot.phase}"

    def _emit(
        self, data: EventData, *, robot: str = "", door: str = "", object: str = "", at: float | None = None
    ) -> None:
        self._events.append(SimEvent(self.time if at is None else at, data, robot, door, object))

    def _new_world(self) -> int:
        self.world_version += 1
        return self.world_version

    def _report(self, outcomes: list[Outcome], t: float) -> None:
        for out in outcomes:
            data = out.data
            if out.new_world:
                data.world_version = self._new_world()
            if out.kind == "action_done":
                self.metrics.actions_done += 1
            elif out.kind == "action_failed":
                self.metrics.actions_failed += 1
            elif out.kind == "delivered":
                self._robot_progress(out.robot, t)
            self._emit(data, robot=out.robot, door=out.door, object=out.object, at=t)

    def _robot_progress(self, rid: str, t: float) -> None:
        mine = self.objects.of_robot(rid)
        if mine and all(o.delivered for o in mine):
            self.metrics.robot_done[rid] = max(o.delivered_at or t for o in mine)

    def _door_change(self, change: DoorChange, t: float) -> None:
        self.door_changed.add(change.door)
        data = (DoorOpened if change.opened else DoorClosed)(by=change.by)
        if self.doors[change.door].human_operated:
            data.world_version = self._new_world()
        if change.opened:
            self.door_by[change.door] = change.by
            # A real door's opening is the human's (or the experimenter's), whatever its sensor calls it.
            self.metrics.opened(change.door, "human" if self.doors[change.door].sensor else change.by)
            if change.until:
                data.until = change.until
        self._emit(data, door=change.door, at=t)

    def _track_waiting(self, t: float) -> None:
        for rid, robot in self.robots.items():
            if robot.state == "waiting_at_door":
                entry = self._waiting_since.get(rid)
                if entry is None or entry[0] != robot.waiting_door:
                    self._waiting_since[rid] = (robot.waiting_door, t)
            else:
                self._waiting_since.pop(rid, None)

    def _human_action(self, action: OpenDoor | Declare | TaskDone, t: float) -> None:
        if isinstance(action, OpenDoor):
            self.doors.human_open(action.door, t)
            self.door_changed.add(action.door)
            self._emit(HumanOpensDoor(opening=self.human.counters.door_openings), door=action.door)
        elif isinstance(action, Declare):
            self._feedback_ids += 1
            request = FeedbackRequest(
                self._feedback_ids, t, "door_unavailable", {"door": action.door, "minutes": action.minutes}
            )
            self._feedback.append(request)
            self.metrics.feedback_sent += 1
            self._emit(
                FeedbackSent(request=request.id, kind=request.kind, params=dict(request.params)), door=action.door
            )
        else:
            self.metrics.human_done = action.time
            self._emit(HumanDone(task_duration=self.human.task_duration), at=action.time)

    def _check_end(self, t: float) -> None:
        finished = self.objects.all_delivered and self.human.done
        timed_out = self.config.time_limit > 0 and t >= self.config.time_limit - 1e-9
        if not (finished or timed_out):
            return
        self.done = True
        self.completed = finished
        self._emit(MissionDone(**self.summary()))

    def summary(self) -> dict[str, Any]:
        robots = {
            rid: {
                "completion_time": self.metrics.robot_done.get(rid),
                "delivered": list(r.delivered),
                "wait_time": round(r.wait_time, 6),
                "yield_time": round(r.yield_time, 6),
            }
            for rid, r in self.robots.items()
        }
        h = self.human
        human = {
            "completion_time": h.done_time,
            "task_duration": h.task_duration,
            "door_openings": h.counters.door_openings,
            "door_trips": h.counters.door_trips,
            "turned_back": h.counters.turned_back,
            "declarations": h.counters.declarations,
            "interruptions": h.counters.interruptions,
            "time_lost": round(h.counters.time_lost, 6),
            "time_away": round(h.counters.time_away, 6),
            "focus": h.focus_report(),
            "focus_started": h.counters.focus_started,
            "anticipated": h.counters.anticipated,
        }
        if isinstance(h, ParticipantHuman):
            human["participant"] = True  # so analysis tells a person's trial from the model's
            human["doors"] = "sensor" if self.door_sensors else "sim"
        out = self.metrics.summary(
            time=self.time,
            completed=self.completed,
            robots=robots,
            human=human,
            world_versions=self.world_version,
            wall_depth_max=self.wall_contacts.deepest,
        )
        if self.end_reason:
            out["reason"] = self.end_reason
        return out


def engine_config_with(**overrides: Any) -> EngineConfig:
    """An :class:`EngineConfig` with the given fields changed (``None`` values are ignored)."""
    return replace(EngineConfig(), **{k: v for k, v in overrides.items() if v is not None})
