"""Executing RobotCommands: one state machine per robot (docs/services/robot.md, execution contract).

One executor for every robot ARROCH drives: the simulator's robots (``services/sim/engine.py``
steps them and applies each step's pose) and a real robot's (``arroch robot --ros2``,
``services/robot/driver.py``: it sends each step's ``(v, omega)`` as the robot's Twist and takes its
next pose from the robot's odometry). Each step is decided from the robot's pose, the doors and the
objects (:mod:`.interfaces`) and the other robots of :attr:`RobotExecutor.fleet`, so a real robot
yields, waits, drives around, makes way, queues and gives up exactly as a simulated one.

An action runs through phases: *drive* (follow the trajectory with :class:`PurePursuit`), then,
depending on the action, *wait for the door* (``opendoor``) or *dwell* (``load``/``unload``
for ``duration``, else the site's ``load_time``), then done. A new command preempts the current
one; an ``action_id`` not above the last one seen is a duplicate or stale and is ignored.

Doors on the way: every door whose gap the path crosses is a *crossing* at some arc length. While
the next crossing's door is not passable, the robot may go no further than ``radius +
stop_margin`` short of the closed leaf's line; held there it is ``waiting_at_door``. A hard guard
backs this up: a step that would bring the robot's disc within ``guard_margin`` of a shut door's
gap, closer than it was, is refused (the robot still turns where it stands). Walls likewise: a
step that takes a disc more than ``wall_tolerance`` (a touch) into a wall, deeper than it was, is
refused (the pursuit's corner cut beside a doorway, heading back onto a trajectory from off it), and the
robot plans its way back on the grid (:meth:`Avoidance.rejoin`). A drive refused so for
``guard_patience`` in a row (a door it does not go through, a wall it has no way round) fails.
Robots never touch (:mod:`.avoidance`): a robot kept back by others that drives around nothing and
gets nobody to make way fails after ``Avoidance.give_up``, and the planner plans again.
Automatic doors are asked to open while the robot's path reaches them within ``auto_open_distance``.

A command that cannot be executed fails at once with ``action_failed`` and a reason: an unknown
door, passage or object, an object that is not this robot's or not where it can be reached, a full
robot, a trajectory that starts too far from the robot, crosses a wall, or (``gothrough``) does
not cross the opening it names.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from protocol.events import ActionDone, ActionFailed, Delivered, Loaded, RobotOutcome, WaitingAtDoor
from protocol.messages import RobotCommand, RobotStatus
from protocol.site.model import Site
from runtime.clearance import wall_clearance
from runtime.execution import REACH, START_TOLERANCE, command_problem, dwell_problem
from runtime.plane import segment_distance
from runtime.pursuit import ControllerConfig, Path, PurePursuit, Step, crossing_behind, path_crossings

from .avoidance import Avoidance
from .doorways import Doorways, in_lane
from .interfaces import Doors, Objects
from .make_way import MakeWay, Request, along
from .right_of_way import RightOfWay
from .waiting import Waits
from .wall_slide import WallSlide
from .walls import TOUCH, WallDepth

QUEUE_DISTANCE = 1.5  # m from the end of its approach within which a robot kept back queues there
BOX_SLACK = 1e-9  # m: the door guard's quick box test errs on the side of the exact one
# m: cells of the grid a robot driving around others keeps to. Half the motion planner's: the clearance
# it needs for the same guarantee (runtime/clearance.py) is 0.043 m instead of 0.066, so a robot in a
# 2 m corridor still finds where to step aside between a robot passing down the middle and the wall
# (twelve robots on the planner's grid jammed the corridor within a minute)
FREE_RESOLUTION = 0.025


def _crossing(robot: Robot) -> str:
    """The opening a robot is driving through (its command is a gothrough), else ""."""
    cmd = robot.command
    return cmd.args[0] if robot.phase == "drive" and cmd is not None and cmd.action == "gothrough" else ""


@dataclass(frozen=True)
class RobotConfig:
    controller: ControllerConfig = ControllerConfig()
    radius: float = 0.25
    load_time: float = 10.0
    capacity: int = 1
    stop_margin: float = 0.15  # m between a waiting robot's disc and a closed leaf's line
    guard_margin: float = 0.05  # m; the hard limit no step may cross toward a shut door
    auto_open_distance: float = 1.5  # m of path ahead within which an automatic door is asked to open
    start_tolerance: float = START_TOLERANCE  # m; a trajectory may start at most this far from the robot
    reach: float = REACH  # m from the robot's centre within which it can pick up an object
    robot_margin: float = 0.05  # m a driving robot keeps between its disc and another robot's
    guard_patience: float = 30.0  # s a drive may be refused by the shut-doorway or wall guard before it fails
    # m a disc may reach into a wall: touching it, no more. (0.05 until the robots sweep found two
    # discs 10-11 mm into a door's jamb, cutting the corner back onto the way in after making way.)
    wall_tolerance: float = TOUCH
    # m added to ``robot_margin`` and to the closest two discs may come (``Avoidance.contact_gap``) for
    # robots that see one another late (a real robot's driver sets it from its control period,
    # services/robot/driver.py: the others' poses are predicted, and this is what the prediction may
    # miss); 0 in the simulator, which steps every robot on the others' latest poses
    allowance: float = 0.0


@dataclass(frozen=True)
class Outcome:
    """Something a robot did that the engine reports (and maybe answers with a new world version)."""

    data: RobotOutcome  # its type is the event's kind: ActionDone, ActionFailed, WaitingAtDoor, Loaded, Delivered
    robot: str
    door: str = ""
    object: str = ""
    new_world: bool = False  # the planner must answer it (world_version increments)

    @property
    def kind(self) -> str:
        return self.data.KIND


class PlanStep(Protocol):
    """The plan step an outcome is about: a robot's command, or a ROS 2 robot's status of it."""

    plan_id: str
    action_id: str
    action: str
    args: Sequence[str]


def outcome_of(
    robot: Robot,
    kind: type[RobotOutcome],
    step: PlanStep | None,
    *,
    door: str = "",
    object: str = "",
    new_world: bool = False,
    reason: str = "",
) -> Outcome:
    """The outcome ``kind`` of ``step`` (None: no step), carrying where the robot is as it happens: a
    consumer can plan from it without relying on the pose stream having arrived first (subscriptions
    on different keys are not ordered)."""
    data = (
        kind()
        if step is None
        else kind(plan_id=step.plan_id, action_id=step.action_id, action=step.action, args=list(step.args))
    )
    data.pose = [round(robot.x, 6), round(robot.y, 6), round(robot.theta, 6)]
    if reason:
        data.reason = reason
    return Outcome(data, robot.id, door=door, object=object, new_world=new_world)


def status_message(robot: Robot, world_version: int) -> RobotStatus:
    """The robot's ``RobotStatus`` now, with the world version its sender last knew."""
    cmd = robot.command
    return RobotStatus(
        robot=robot.id,
        state=robot.state,
        plan_id=cmd.plan_id if cmd else 0,
        action_id=cmd.action_id if cmd else 0,
        action=cmd.action if cmd else "",
        args=list(cmd.args) if cmd else [],
        progress=max(0.0, min(1.0, robot.progress)),
        carrying=list(robot.carrying),
        delivered=list(robot.delivered),
        waiting_door=robot.waiting_door,
        detail=robot.detail[:512],
        world_version=world_version,
    )


class CommandError(Exception):
    """Why a command cannot be executed (the text goes into action_failed's reason)."""


@dataclass
class Robot:
    id: str
    x: float
    y: float
    theta: float
    v: float = 0.0
    omega: float = 0.0
    state: str = "idle"  # RobotStatus.state
    command: RobotCommand | None = None
    last_action_id: int = 0
    carrying: list[str] = field(default_factory=list)
    delivered: list[str] = field(default_factory=list)
    waiting_door: str = ""
    detail: str = ""
    progress: float = 0.0
    wait_time: float = 0.0  # s spent waiting at doors, over the whole mission
    yield_time: float = 0.0  # s spent stopped for another robot or on a hold of its trajectory
    # execution of the current command
    phase: str = "idle"  # idle, drive, wait_open, dwell, done, failed
    follower: PurePursuit | None = None
    crossings: list[tuple[float, str]] = field(default_factory=list)  # (arc length, door id), in order
    dwell_left: float = 0.0
    dwell_total: float = 0.0
    refused_time: float = 0.0  # s the drive's steps have been refused by the shut-doorway or wall guard in a row
    status_changed: bool = True


class RobotExecutor:
    """Applies commands to robots and steps them; shared rules, one instance per engine."""

    def __init__(self, site: Site, doors: Doors, objects: Objects, config: RobotConfig) -> None:
        self.site = site
        self.doors = doors
        self.objects = objects
        self.config = config
        self.fleet: dict[str, Robot] = {}  # every robot, for the right of way (set by the engine)
        self.right_of_way = RightOfWay(config.radius, config.robot_margin + config.allowance)
        # where a robot's centre may go when it drives around another (doors open: shut ones are checked
        # apart): inflated as the motion planner's grid is, so a way around never touches a wall either
        self._free = site.occupancy_grid(
            resolution=FREE_RESOLUTION,
            open_doors=tuple(site.door_leaves),
            inflate=config.radius + wall_clearance(FREE_RESOLUTION),
        )
        self._walls = WallDepth(site, config.radius)
        self.wall_slide = WallSlide(self._walls, config.wall_tolerance, config.controller)
        self.avoidance = Avoidance(site, self._free, config.radius, config.controller)
        self.avoidance.contact_gap += config.allowance
        self.doorways = Doorways(site)
        self.avoidance.keep_out = lambda robot: self.doorways.held_lanes(robot, self.fleet)
        self.avoidance.passable = lambda opening_id: opening_id not in doors.doors or doors.passable(opening_id)
        self.make_way = MakeWay(config.radius, self.doorways.holds)
        self.waits = Waits()
        self._made_way: set[str] = set()  # robots answering a request to make way
        self._passed_on: dict[str, float] = {}  # robot -> when it last looked for a robot boxing it in
        self._offered: dict[str, int] = {}  # robot -> the action in which it made way unasked (once per action)
        # robot -> (action, robot making way for it) for which it handed its doorway back (once per action)
        self._handed_back: dict[str, tuple[int, str]] = {}

    # ------------------------------------------------------------------ commands

    def assign(self, robot: Robot, cmd: RobotCommand) -> list[Outcome]:
        """Start executing ``cmd`` (preempting what ran before). Returns what that caused at once."""
        self._take(robot, cmd)
        if cmd.action == "stop":
            robot.phase = "idle"
            self._set(robot, state="idle", detail="stopped")
            # Nothing the planner did not ask for: no new world version (a stop per plan would loop).
            return [self._outcome(robot, ActionDone)]
        try:
            self._check(robot, cmd)
        except CommandError as exc:
            return self._fail(robot, str(exc))
        if cmd.trajectory:
            robot.follower = PurePursuit(Path(cmd.trajectory), self.config.controller)
            robot.crossings = self._crossings(robot.follower.path)
        robot.phase = "drive"
        return []

    def refuse(self, robot: Robot, cmd: RobotCommand, reason: str) -> list[Outcome]:
        """Take ``cmd`` and fail it at once, for a reason only the caller knows (a real robot whose
        pose has not come yet)."""
        self._take(robot, cmd)
        return self._fail(robot, reason)

    def _take(self, robot: Robot, cmd: RobotCommand) -> None:
        """``cmd`` is the robot's command from now on: what ran before is over."""
        robot.command = cmd
        robot.last_action_id = cmd.action_id
        self.doorways.forget(robot.id)
        self.avoidance.moving_on(robot.id)  # how long it was kept back on its last drive counts no more
        robot.follower = None
        robot.crossings = []
        robot.refused_time = 0.0
        robot.v = robot.omega = 0.0
        robot.detail = ""
        robot.progress = 0.0
        robot.status_changed = True  # a new action_id, even if the state stays "moving"
        self._set(robot, state="moving", waiting_door="")

    def _check(self, robot: Robot, cmd: RobotCommand) -> None:
        target = cmd.args[0] if cmd.args else ""
        if cmd.action in ("load", "unload"):
            if target not in self.objects:
                raise CommandError(f"{cmd.action}: no object {target!r}")
            objects = self.objects
            if cmd.action == "load":
                if objects.owner(target) != robot.id:
                    raise CommandError(f"load: object {target!r} belongs to robot {objects.owner(target)!r}")
                if objects.delivered(target) or objects.carrier(target) is not None:
                    raise CommandError(
                        f"load: object {target!r} is "
                        f"{'delivered' if objects.delivered(target) else 'carried by ' + str(objects.carrier(target))}"
                    )
                if len(robot.carrying) >= self.config.capacity:
                    raise CommandError(f"load: robot is full ({self.config.capacity} object(s))")
            elif target not in robot.carrying:
                raise CommandError(f"unload: robot does not carry {target!r}")
        problem = command_problem(self.site, robot.x, robot.y, cmd, self.config.start_tolerance)
        if problem:
            raise CommandError(problem)

    def _crossings(self, path: Path) -> list[tuple[float, str]]:
        return path_crossings(path, {door.id: door.gap for door in self.doors.doors.values()})

    # ------------------------------------------------------------------ stepping

    def step(self, robot: Robot, now: float, dt: float) -> list[Outcome]:
        """Advance one robot by ``dt``; ``now`` is the time at the start of the step."""
        making_way = self._making_way(robot, now, dt)
        if making_way or robot.phase != "drive":
            self.waits.off(robot.id)  # it waits for no robot: it makes way, dwells or waits for a door
        if making_way:
            return []
        if robot.phase == "drive":
            return self._drive(robot, now, dt)
        self.right_of_way.forget(robot.id)  # waits for no robot
        if robot.phase == "wait_open":
            return self._wait_open(robot, dt)
        if robot.phase == "dwell":
            return self._dwell(robot, now, dt)
        robot.v = robot.omega = 0.0
        return []

    def _drive(self, robot: Robot, now: float, dt: float) -> list[Outcome]:
        follower = robot.follower
        if follower is None:
            return self._arrived(robot, now + dt)
        lane = self.doorways.lane_to_leave(robot, self.fleet)
        if lane is not None:
            # in the lane of an opening another robot crosses: out of its way first
            away = self.avoidance.out_of_the_way(
                robot, robot.theta, now, dt, self.fleet, lambda x, y: not in_lane(lane, x, y), self._allows(robot)
            )
            if away is not None:
                robot.x, robot.y, robot.theta, robot.v, robot.omega = away.x, away.y, away.theta, away.v, away.omega
                robot.yield_time += dt
                return []
        opening_id = _crossing(robot)
        kept_back_by = self.waits.waits_for.get(robot.id, "")  # last step's (it may still drive around it)
        self.waits.off(robot.id)  # until a robot keeps it back below
        letting = self._lets_way_be_made(robot)
        if opening_id and (letting or not self.doorways.may_cross(robot, opening_id, now, self.fleet)):
            robot.v = robot.omega = 0.0  # another robot has the doorway (or is to get out through it): wait
            holder = self._handed_back[robot.id][1] if letting else self.doorways.holders.get(opening_id)
            if holder is not None:
                self.waits.on(robot.id, holder)
            robot.yield_time += dt
            self.avoidance.moving_on(robot.id)
            return []
        cfg = self.config
        s_limit, blocking = math.inf, ""
        for s_cross, door_id in robot.crossings:
            if crossing_behind(follower.path, s_cross, self.doors[door_id].gap, follower.s, robot.x, robot.y):
                continue  # behind the robot's centre already
            if s_cross - follower.s <= cfg.auto_open_distance + cfg.radius:
                self.doors.request_open(door_id, robot.id)
            if not self.doors.passable(door_id):
                s_limit, blocking = s_cross - (cfg.radius + cfg.stop_margin), door_id
                break
        cmd = robot.command
        if cmd is not None and cmd.action == "approach":
            # Approaching a door to go through it next: an automatic one opens as the robot comes
            # near, so it does not have to stop at it when gothrough follows.
            opening = self.site.opening(cmd.args[0])
            if (
                opening.kind == "door"
                and math.dist((robot.x, robot.y), opening.center) <= cfg.auto_open_distance + cfg.radius
            ):
                self.doors.request_open(opening.id, robot.id)
        hold = follower.path.hold_limit(now)
        if hold < s_limit:
            s_limit, blocking = hold, ""  # the plan says wait here (for another robot) until then
        step = follower.step(robot.x, robot.y, robot.theta, dt, s_limit)
        if blocking and not step.held and self._breaks_guard(robot, step, blocking):
            step = Step(robot.x, robot.y, robot.theta, 0.0, 0.0, held=True)
        if not step.held and follower.cross_track > self.avoidance.rejoin_after:
            self.avoidance.rejoin(robot, follower.path, follower.s, now, self.fleet, off_track=True)
        if step.held:
            self.right_of_way.forget(robot.id)  # waits for a door or a hold, not for a robot
            self.avoidance.moving_on(robot.id)
        elif holder := self.doorways.lane_holder(robot, step.x, step.y, self.fleet):
            # the way ahead crosses a doorway's lane another robot holds: wait for it, like for a door
            self.waits.on(robot.id, holder)
            robot.v = robot.omega = 0.0
            robot.yield_time += dt
            self.avoidance.moving_on(robot.id)
            return []
        elif (
            (blocker := self.right_of_way.blocker(robot, step.x, step.y, self.fleet, now))
            or (blocker := self.avoidance.closing_in_on(robot, step.x, step.y, self.fleet))
            or self.avoidance.driving_around(robot.id)
        ):
            self.waits.on(robot.id, blocker or kept_back_by)
            if self._goal_taken(robot, follower, now):
                robot.v = robot.omega = 0.0
                return self._arrived(robot, now + dt)
            kept = self.avoidance.mark_kept_back(robot, now)
            stuck_for = self.waits.stuck_for(robot.id, self.fleet, now)  # every step kept back: its clock runs
            stuck = kept >= self.avoidance.give_up and stuck_for >= self.avoidance.give_up
            waited = self.waits.waited(robot.id, now, counts=not self._queued_at_door(robot))
            out_of_patience = kept >= self.waits.patience and waited >= self.waits.patience
            if stuck or out_of_patience:
                # wedged among robots (a cycle, or behind a parked one) with no way around and
                # nobody making way: it never pushes through; the planner plans again from here
                robot.v = robot.omega = 0.0
                self.avoidance.moving_on(robot.id)
                if (stuck and self._make_way_unasked(robot, now)) or self._hand_doorway_back(robot, now):
                    return []
                limit = self.avoidance.give_up if stuck else self.waits.patience
                chain = " -> ".join(self.waits.chain(robot.id))
                self.waits.gave_up(robot.id)
                return self._fail(robot, f"kept back by robots for {limit:g} s (waiting: {chain})")
            step = self._kept_back(robot, follower, now, dt)
            robot.yield_time += dt
            self.wall_slide.forget(robot.id)  # driven around robots now, on the grid's free cells
        elif step.v > 0.0:
            self.avoidance.moving_on(robot.id)
        if step.held:
            self.wall_slide.forget(robot.id)
        elif not self.avoidance.driving_around(robot.id):
            # the pursuit cutting a jamb's corner: the robot goes along the wall instead, while it may
            step = self.wall_slide.step(robot, step, dt)
        moved = (step.x, step.y) != (robot.x, robot.y)
        refused_by = "a shut door's gap" if moved and self._into_shut_doorway(robot, step) else ""
        if moved and not refused_by and self._into_wall(robot, step):
            refused_by = "a wall"
            # the way on lies past a wall's end, with no way along the wall: plan it on the grid
            self.wall_slide.forget(robot.id)
            self.avoidance.rejoin(robot, follower.path, follower.s, now, self.fleet, off_track=True)
        if refused_by or (moved and not self.avoidance.clear(robot, step.x, step.y, self.fleet)):
            # whatever moved it (driving around, a hold, a corner): its disc never enters a shut doorway
            # (passing beside one, a corridor along a row of doors, is allowed) nor a wall, nor
            # touches a robot. It still turns, where it stands: a robot facing the gap it must not
            # come nearer would otherwise never face its way out again.
            step = Step(robot.x, robot.y, step.theta, 0.0, step.omega)
        if self._held_back(robot, bool(refused_by), dt):
            return self._fail(robot, f"held beside {refused_by} for {self.config.guard_patience:g} s")
        robot.x, robot.y, robot.theta, robot.v, robot.omega = step.x, step.y, step.theta, step.v, step.omega
        robot.progress = min(follower.s / follower.path.length, 1.0) if follower.path.length > 0 else 1.0
        if step.held and not blocking:
            robot.yield_time += dt
            if robot.state == "waiting_at_door":
                self._set(robot, state="moving", waiting_door="")
            return []
        if step.held:
            robot.wait_time += dt
            if robot.state != "waiting_at_door" or robot.waiting_door != blocking:
                self._set(robot, state="waiting_at_door", waiting_door=blocking)
                return [self._outcome(robot, WaitingAtDoor, door=blocking)]
            return []
        if robot.state == "waiting_at_door":
            self._set(robot, state="moving", waiting_door="")
        if step.arrived:
            return self._arrived(robot, now + dt)
        return []

    def motion_params(self) -> dict[str, float]:
        """How robots keep clear of walls and of one another (the metrics' params: a report quotes them)."""
        return {
            "wall_tolerance": self.config.wall_tolerance,
            "guard_patience": self.config.guard_patience,
            "robot_margin": self.config.robot_margin,
            "detour_after": self.avoidance.detour_after,
            "ask_after": self.make_way.ask_after,
            "give_up": self.avoidance.give_up,
        }

    def _held_back(self, robot: Robot, refused: bool, dt: float) -> bool:
        """Whether the robot's drive has been refused by the shut-doorway or wall guard for too long:
        a door it does not go through (it would report ``waiting_at_door`` for one it does), so
        nobody opens it, or a wall it finds no way round; the action fails and the planner plans
        again from where the robot stands."""
        robot.refused_time = robot.refused_time + dt if refused else 0.0
        return robot.refused_time >= self.config.guard_patience

    def _goal_taken(self, robot: Robot, follower: PurePursuit, now: float) -> bool:
        """Whether a robot kept back near the end of an approach, a gothrough (through the opening)
        or the drive of an unload (in the room the object goes to) finds another robot standing
        there: it is done where it is (queueing behind, or unloading beside it)."""
        cmd = robot.command
        if cmd is None or cmd.action not in ("approach", "gothrough", "unload"):
            return False
        end = follower.path.end
        if math.dist((robot.x, robot.y), end) > QUEUE_DISTANCE or self.avoidance.kept_back(robot.id, now) < 1.0:
            return False
        if any(in_lane(o, robot.x, robot.y) for o in self.site.openings.values()):
            return False  # never queue in a lane: it is the way out of a doorway
        if cmd.action == "unload" and dwell_problem(self.site, robot.x, robot.y, cmd, (robot.x, robot.y)):
            return False
        if cmd.action == "gothrough":
            opening = self.site.opening(cmd.args[0])
            if not crossing_behind(
                follower.path, follower.path.length / 2, opening.endpoints, follower.s, robot.x, robot.y
            ):
                return False
        taken = 2.0 * self.config.radius + self.avoidance.clearance
        return any(other is not robot and math.dist((other.x, other.y), end) < taken for other in self.fleet.values())

    def _queued_at_door(self, robot: Robot) -> bool:
        """Whether the robot queues behind robots the first of which waits for a door to open (the
        chain of waits ends there): the queue moves when the door opens, however long that takes (a
        human at her task, one who declared herself unavailable for minutes), and giving up would
        only send the robot back to its place in the queue - so that time does not count toward
        ``patience`` (:meth:`.waiting.Waits.waited`)."""
        head = self.waits.head(robot.id)
        other = self.fleet.get(head) if head else None
        return other is not None and (other.phase == "wait_open" or other.state == "waiting_at_door")

    def _kept_back(self, robot: Robot, follower: PurePursuit, now: float, dt: float) -> Step:
        """Another robot is in the way: drive around it after a while (:mod:`.avoidance`), ask it
        to make way when that does not get the robot anywhere (:mod:`.make_way`), else stop."""
        stop = Step(robot.x, robot.y, robot.theta, 0.0, 0.0)
        if self.avoidance.kept_back(robot.id, now) >= self.make_way.ask_after:
            way = self.make_way.way_ahead(follower.path, follower.s)
            other = self.make_way.in_the_way(robot, way, self.fleet)
            if other is not None and self.make_way.ask(robot, other, way, now):
                self.avoidance.stop_driving_around(robot.id)  # it waits for the other to make way
                return stop
        around = self.avoidance.around(
            robot, robot.theta, follower.path, follower.s, now, dt, self.fleet, self._allows(robot)
        )
        return around if around is not None else stop

    def _making_way(self, robot: Robot, now: float, dt: float) -> bool:
        """Whether the robot spends this step making way for another (:mod:`.make_way`): stepping
        off the other's way, or waiting off it until the other has gone past."""
        if robot.phase == "dwell":
            return False
        request = self.make_way.request_for(robot, now, self.fleet)
        if request is None:
            if robot.id in self._made_way:  # the other has gone past: back to its own business
                self._made_way.discard(robot.id)
                self.avoidance.moving_on(robot.id)
            return False
        if robot.id not in self._made_way:
            self._made_way.add(robot.id)
            self.avoidance.moving_on(robot.id)  # its own way around, if any, is not where it goes now
        robot.yield_time += dt
        self.avoidance.not_kept_back(robot.id)  # it waits for nobody: it never gives up
        step = None
        if self._in_the_way(robot, request):
            step = self.avoidance.out_of_the_way(
                robot,
                robot.theta,
                now,
                dt,
                self.fleet,
                lambda x, y: self.make_way.off_the_way(request, x, y),
                self._allows(robot),
            )
        if step is None and not self.avoidance.driving_around(robot.id):
            self._pass_on(robot, request, now)
        if step is None or self._into_shut_doorway(robot, step):
            robot.v = robot.omega = 0.0
            return True
        robot.x, robot.y, robot.theta, robot.v, robot.omega = step.x, step.y, step.theta, step.v, step.omega
        return True

    def _make_way_unasked(self, robot: Robot, now: float) -> bool:
        """The last resort of a robot in a waiting cycle, before its action fails: make way for the
        robot of the cycle that waits on it (:meth:`.make_way.MakeWay.offer`), once per action, when
        there is a free point off that robot's way. A failed action alone breaks no cycle: the replan
        leaves both robots where they stand, and they wait on each other again."""
        chain = self.waits.chain(robot.id)
        if len(chain) < 3 or chain[-1] != robot.id or self._offered.get(robot.id) == robot.last_action_id:
            return False  # not in a cycle itself (queued behind one), or it made way once in this action
        waiting = self.fleet.get(chain[-2])
        if waiting is None:
            return False
        request = self.make_way.offer(robot, waiting, now)
        if not self.avoidance.way_off(robot, self.fleet, lambda x, y: self.make_way.off_the_way(request, x, y)):
            self.make_way.forget(robot.id)
            return False
        self._offered[robot.id] = robot.last_action_id
        self.waits.gave_up(robot.id)  # its wait is over; the robots it waited on get ``give_up`` afresh
        return True

    def _hand_doorway_back(self, robot: Robot, now: float) -> bool:
        """The last resort of a robot holding a doorway it has not entered, kept back by a robot
        making way for it, before its action fails: that robot may be boxed in by the doorway's lane
        (no robot steps into a lane another holds), so it hands the doorway back, asks afresh, and
        takes the doorway again once the other is off its way (:meth:`_lets_way_be_made`); once
        per action."""
        other = self.waits.waits_for.get(robot.id, "")
        request = self.make_way.requests.get(other)
        if request is None or request.first_asker != robot.id or other not in self.fleet:
            return False
        if self._handed_back.get(robot.id, (None, ""))[0] == robot.last_action_id:
            return False
        if not self.doorways.hand_back(robot.id):
            return False
        request.since = request.renewed = now  # a fresh request: the other has its full time to make way
        self._handed_back[robot.id] = (robot.last_action_id, other)
        self.waits.gave_up(robot.id)  # its wait is over; the robots it waited on get ``give_up`` afresh
        return True

    def _lets_way_be_made(self, robot: Robot) -> bool:
        """Whether the robot, having handed its doorway back (:meth:`_hand_doorway_back`), still waits
        for the robot making way for it to get off its way before it takes the doorway again."""
        handed = self._handed_back.get(robot.id)
        if handed is None or handed[0] != robot.last_action_id:
            return False
        other = self.fleet.get(handed[1])
        request = self.make_way.requests.get(handed[1])
        if other is None or request is None or request.first_asker != robot.id:
            return False
        return not self.make_way.off_the_way(request, other.x, other.y)

    def _in_the_way(self, robot: Robot, request: Request) -> bool:
        """Whether the robot asked still stands in the asker's way: on the way's points, or off
        them but still what the asker stops for (its drive cuts a corner nearer than the points)."""
        return (
            not self.make_way.off_the_way(request, robot.x, robot.y)
            or self.right_of_way.blocked_by.get(request.asker) == robot.id
        )

    def _pass_on(self, robot: Robot, request: Request, now: float) -> None:
        """Boxed in while making way: ask the robot standing where it could go to make way in turn
        (at most once per ``avoidance.retry``: it is a search of the room)."""
        if self._in_the_way(robot, request) and (
            now - self._passed_on.get(robot.id, -math.inf) >= self.avoidance.retry
        ):
            self._passed_on[robot.id] = now
            found = self.avoidance.boxed_in_by(
                robot,
                self.fleet,
                lambda x, y: self.make_way.off_the_way(request, x, y),
                lambda other: other.phase != "dwell" and other.id != request.first_asker,
            )
            if found is not None:
                other, escape = found
                self.make_way.pass_on(robot, other, along(escape, self.make_way.step), now)

    def _allows(self, robot: Robot):
        """What a step off the trajectory must not do: enter a shut doorway, a wall or a lane another robot holds."""

        def allowed(candidate: Step) -> bool:
            return (
                not self._into_shut_doorway(robot, candidate)
                and not self._into_wall(robot, candidate)
                and not self.doorways.lane_taken(robot, candidate.x, candidate.y, self.fleet)
            )

        return allowed

    def _into_shut_doorway(self, robot: Robot, step: Step) -> bool:
        """Whether ``step`` brings the robot's disc into the gap of a door that is not passable, or
        (a leaf on the move) into the area the leaf sweeps."""
        for door in self.doors.doors.values():
            if door.passable:
                continue
            if self._breaks_guard(robot, step, door.id, 0.0):
                return True
            if self.doors.into_swing(door.id, (robot.x, robot.y), (step.x, step.y)):
                return True
        return False

    def _into_wall(self, robot: Robot, step: Step) -> bool:
        """Whether ``step`` takes the robot's disc more than ``wall_tolerance`` into a wall, deeper
        than it was (sliding along a wall, or getting out of one, is allowed)."""
        return self.wall_slide.into_wall(robot.x, robot.y, step.x, step.y)

    def _breaks_guard(self, robot: Robot, step: Step, door_id: str, margin: float | None = None) -> bool:
        a, b = self.doors[door_id].gap
        limit = self.config.radius + (self.config.guard_margin if margin is None else margin)
        # A step farther than ``limit`` from the gap's (axis-aligned) box along an axis is farther
        # than ``limit`` from the gap: it breaks nothing, without the two exact distances.
        reach = limit + BOX_SLACK  # so float rounding never skips a step the exact distances refuse
        if not (a[0] - reach < step.x < b[0] + reach and a[1] - reach < step.y < b[1] + reach):
            return False
        before = segment_distance((robot.x, robot.y), a, b)
        after = segment_distance((step.x, step.y), a, b)
        return after < limit and after < before

    def _arrived(self, robot: Robot, t: float) -> list[Outcome]:
        """The drive is over; go on with what the action does at its end."""
        cmd = robot.command
        assert cmd is not None
        robot.v = robot.omega = 0.0
        if cmd.action in ("approach", "gothrough"):
            return self._done(robot)
        if cmd.action == "opendoor":
            robot.phase = "wait_open"
            return self._wait_open(robot, 0.0)
        # load / unload: check now that the dwell can succeed, so a doomed one fails at once.
        where = self.objects.position(cmd.args[0])
        problem = dwell_problem(self.site, robot.x, robot.y, cmd, where, self.config.reach)
        if problem:
            return self._fail(robot, problem)
        robot.phase = "dwell"
        robot.dwell_total = robot.dwell_left = cmd.duration if cmd.duration > 0 else self.config.load_time
        robot.progress = 0.0
        self._set(robot, state="loading" if cmd.action == "load" else "unloading")
        if robot.dwell_left <= 0:
            return self._dwell(robot, t, 0.0)
        return []

    def _wait_open(self, robot: Robot, dt: float) -> list[Outcome]:
        cmd = robot.command
        assert cmd is not None
        door_id = cmd.args[0]
        self.doors.request_open(door_id, robot.id)
        if self.doors.passable(door_id):
            return self._done(robot)
        robot.wait_time += dt
        if robot.state != "waiting_at_door":
            self._set(robot, state="waiting_at_door", waiting_door=door_id)
            return [self._outcome(robot, WaitingAtDoor, door=door_id)]
        return []

    def _dwell(self, robot: Robot, now: float, dt: float) -> list[Outcome]:
        cmd = robot.command
        assert cmd is not None
        robot.dwell_left -= dt
        robot.progress = min(1.0, 1.0 - robot.dwell_left / robot.dwell_total) if robot.dwell_total > 0 else 1.0
        if robot.dwell_left > 1e-9:
            return []
        oid = cmd.args[0]
        # The dwell ended within this step: date what follows at that instant, not at the tick.
        t = now + dt + min(robot.dwell_left, 0.0)
        if cmd.action == "load":
            self.objects.pick(oid, robot.id)
            robot.carrying.append(oid)
            first = self._outcome(robot, Loaded, object=oid)
        else:
            robot.carrying.remove(oid)
            robot.delivered.append(oid)
            self.objects.place(oid, robot.x, robot.y, delivered_at=t)
            first = self._outcome(robot, Delivered, object=oid)
        return [first, *self._done(robot)]

    # ------------------------------------------------------------------ what the executor is told

    def fail(self, robot: Robot, reason: str) -> list[Outcome]:
        """The robot's action fails for a reason the executor does not see itself (a real robot's
        laser safety field blocked for too long): it stops, and the planner plans again."""
        return self._fail(robot, reason)

    def note(self, robot: Robot, detail: str) -> None:
        """Say why a driving robot does not move though its executor drives it (an obstacle its laser
        sees); "" when that is over."""
        if robot.phase == "drive":
            self._set(robot, detail=detail)

    def making_way(self, robot: str) -> bool:
        """Whether the robot answers a request to make way (it may move, whatever its phase)."""
        return robot in self._made_way

    # ------------------------------------------------------------------ reporting

    def _done(self, robot: Robot) -> list[Outcome]:
        robot.phase = "done"
        robot.progress = 1.0
        self._set(robot, state="done", waiting_door="")
        return [self._outcome(robot, ActionDone, new_world=True)]

    def _fail(self, robot: Robot, reason: str) -> list[Outcome]:
        robot.phase = "failed"
        robot.v = robot.omega = 0.0
        self._set(robot, state="failed", waiting_door="", detail=reason)
        return [self._outcome(robot, ActionFailed, new_world=True, reason=reason)]

    def _outcome(
        self,
        robot: Robot,
        kind: type[RobotOutcome],
        *,
        door: str = "",
        object: str = "",
        new_world: bool = False,
        reason: str = "",
    ) -> Outcome:
        return outcome_of(robot, kind, robot.command, door=door, object=object, new_world=new_world, reason=reason)

    @staticmethod
    def _set(robot: Robot, **changes: Any) -> None:
        for name, value in changes.items():
            if getattr(robot, name) != value:
                setattr(robot, name, value)
                robot.status_changed = True
