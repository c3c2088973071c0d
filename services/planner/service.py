"""The planner service: keeps the world, plans, dispatches front actions, replans (Algorithm 1).

Inputs: robot poses and statuses, door states, the ConstraintSet, events (action done/failed),
and the clock (its ``world_version``). Outputs: the TeamPlan on ``plan`` (also served to late
joiners), each robot's RobotCommand for its front action and its Intent, and ``plan_conflict``
events.

When it replans: at start; on a new ConstraintSet; when a robot's action ends, fails, or the robot
reports a new state for it; when a robot is far off its trajectory; when a human-operated door opens
or closes; and on every new ``world_version`` - every one is answered with a TeamPlan, even if
nothing changed, because the simulator's lockstep mode waits for that answer. Triggers arriving
together (a clock tick, a status and an event for one action) are answered by one replan: the
planner waits until SETTLE has passed without news - except in lockstep, where the simulator says
when it has stopped and what for (the Clock's ``awaiting``). When it waits for a plan newer than
the last one published, everything of that world version has arrived (it was published before the
clock), so the plan is made at once (:meth:`_plan_if_awaited`); while it waits for the ack of the
human's feedback, the planner does nothing: the ack brings a new ConstraintSet and a clock awaiting
a plan that answers it. A plan made on a wall-clock delay (SETTLE) before the version's clock came
would start from whatever part of that version had arrived, which depends on the machine's load
(:meth:`_version_complete`); planning only at those fixed points is what makes a lockstep mission the
same on a busy machine as on an idle one, and fast: a mission has a world version every few site
seconds. For the same reason, in lockstep a robot far off its trajectory is found at plan time, from
the poses of that instant, not from poses that fell between two versions.

A burst that only brings robots' actions ending when the plan said or earlier (at most
CONTINUE_TOLERANCE late), or a new world version the plan need not answer (a robot-operated door
opening), keeps the plan being executed, moved past those actions, without running the task planner
(:meth:`continued`).
Replanning starts from the plan being executed (IIDP warm start). When the constraints leave a
robot no plan, the service publishes ``plan_conflict`` naming the constraints that conflict, keeps
planning with the last constraint set that worked (so the plan it keeps is the last valid one,
brought up to date), and keeps running.

A planner (re)started while a mission is under way knows nothing of it: it plans only once every
robot's pose and status have arrived (the simulator repeats them once a wall second, also while
lockstep time stands still), with the live ConstraintSet it fetched at start, so its first plan
starts from where the robots are and what they carry and have delivered. The actions robots are
executing (their statuses name them) are taken over as the ones sent: a plan that keeps them lets
them run on, with the same action ids, instead of starting them again. With the simulator's clock
(``--clock sim``) nothing is planned before that clock ticks: a plan made from the site's start
before the simulator is up would be the warm start of its first real plan, and the mission would
depend on how fast the simulator started. On the wall clock, when nothing has been heard of any
robot after START_GRACE, no mission is running yet and the plan starts from the site's start.

A TeamPlan lost on its way (the router restarting, a link down) would leave a lockstep simulator
waiting for it forever: nothing changes, so nothing triggers a new one. While the simulator's clock
says it is paused at a world version the current plan answers, the plan is published again (same
``plan_id``) every REPEAT_AFTER wall seconds. Lost commands are sent again from the robots'
statuses (see :meth:`PlannerService._resend`).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace

from protocol.clock import SimClock, WallClock
from protocol.messages import (
    Clock,
    ConstraintSet,
    DoorState,
    Event,
    PlannedOpening,
    PlanStep,
    RobotPose,
    RobotStatus,
    TeamPlan,
)
from protocol.service import Service
from protocol.site import Site
from protocol.transport import ZenohOptions

from .constraints import ConstraintProgram, from_constraint_set
from .dispatcher import FINISHED_STATES, Dispatched, Dispatcher
from .motion import polyline_distance
from .plan import TeamResult
from .planner import PlannerSettings, TaskPlanner
from .teammotion import TeamMotion
from .world import InProgress, RobotState, World

SETTLE = 0.03  # s without a new trigger before replanning (one replan for a burst)
MAX_DELAY = 0.25  # s: replan at the latest this long after the first trigger
OFF_TRACK = 1.0  # m from the commanded trajectory that counts as "far off"
OFF_TRACK_COOLDOWN = 2.0  # s between two off-track replans for one robot
CONTINUE_TOLERANCE = 2.0  # s: an action that ends at most this late keeps the plan (no re-solve)
ROUTINE_STATES = ("moving", "done", "loading", "unloading")  # states a plan being followed goes through
LOCKSTEP_TRIGGERS = ("world_version", "constraints", "start")  # news a lockstep simulator waits for a plan about
RESEND_INTERVAL = 1.0  # wall s after sending a command before it is sent again (robot reports no such id)
START_GRACE = (
    1.5  # wall s to hear a mission under way (statuses come once a second) before planning from the site's start
)
STATE_WAIT = 5.0  # wall s to wait for the last robots' poses and statuses before planning without them
REPEAT_AFTER = 2.0  # wall s the simulator may stay paused at a version the plan answers before the plan is sent again


@dataclass
class ServiceSettings:
    method: str = "iidp"
    planner: PlannerSettings = field(default_factory=lambda: PlannerSettings(time_limit=5.0))
    off_track: float = OFF_TRACK
    collision_free: bool = True  # time trajectories against each other (services/planner/teammotion.py)


class PlannerService(Service):
    def __init__(
        self,
        site: Site,
        namespace: str,
        zenoh_options: ZenohOptions,
        *,
        clock: WallClock | SimClock | None = None,
        settings: ServiceSettings | None = None,
        instance: str | None = None,
    ) -> None:
        super().__init__("planner", namespace, zenoh_options, clock=clock, instance=instance)
        self.site = site
        self.settings = settings or ServiceSettings()
        self.planner = TaskPlanner(site, self.settings.planner)
        self.dispatcher = Dispatcher(self.planner.builder, self.planner.motion)
        if self.settings.collision_free:
            self.dispatcher.team = TeamMotion(self.planner.motion)
        self.poses: dict[str, tuple[float, float, float]] = {}
        self.statuses: dict[str, RobotStatus] = {}
        self.doors: dict[str, DoorState] = {}
        self.constraint_set: ConstraintSet | None = None
        self.constraints: ConstraintProgram | None = None
        self.valid_constraints: ConstraintProgram | None = None  # the last set that left a plan
        self.reported_conflicts: set[tuple] = set()
        self.world_version = 0
        self.result: TeamResult | None = None
        self.message: TeamPlan | None = None
        # plan ids keep increasing across restarts of the service
        self.plan_id = int(time.time() * 1000)
        self._dirty: set[str] = set()
        self._first_trigger = 0.0
        self._last_trigger = 0.0
        self._held = False  # pending news waits for the next world version (lockstep)
        self._finished: set[str] = set()
        self._force: set[str] = set()
        self._off_track_at: dict[str, float] = {}
        self._sent_at: dict[str, float] = {}
        self._started_at = time.monotonic()
        self._state_wait_since: float | None = None  # when planning started to wait for the robots' state
        self._state_wait_reported = False
        # (world version, sim time) the simulator is paused at, and since when (wall); None while it runs
        self._paused: tuple[tuple[int, float], float] | None = None
        self._repeated_at = 0.0
        self._sim_clock: Clock | None = None  # the simulator's latest clock message

    # ------------------------------------------------------------------ wiring

    def setup(self) -> None:
        k = self.keys
        # Ordered: handled in the order they came, so a lockstep simulator's clock, published after
        # everything of its world version, is handled after all of it (_plan_if_awaited).
        self.subscribe(k.robot_pose("*"), RobotPose, self.on_pose, latest=True, ordered=True)
        self.subscribe(k.robot_status("*"), RobotStatus, self.on_status, ordered=True)
        self.subscribe(k.door_state("*"), DoorState, self.on_door, ordered=True)
        self.subscribe(k.constraints(), ConstraintSet, self.on_constraints, ordered=True)
        self.subscribe(k.event(), Event, self.on_event, ordered=True)
        self.subscribe(k.clock(), Clock, self.on_clock, ordered=True)
        self.serve(k.plan(), lambda _query: self.message)
        self.every(0.02, self.tick)
        try:  # a restarted planner picks up the active constraints at once
            for cs in self.query(k.constraints(), ConstraintSet, timeout=1.0):
                self.on_constraints(cs, k.constraints())
        except Exception as exc:  # no restrictor yet: its first ConstraintSet will come by pub/sub
            self.log.debug("no constraints to fetch at start: %s", exc)
        self.trigger("start")

    def trigger(self, reason: str) -> None:
        now = time.monotonic()
        if not self._dirty or (self._held and reason.partition(":")[0] in LOCKSTEP_TRIGGERS):
            self._first_trigger = now  # a burst starts (held news joins the one a new version starts)
            self._held = False
        self._last_trigger = now
        self._dirty.add(reason)

    def _hold_for_world_version(self) -> bool:
        """In lockstep, whether the pending news waits for the next world version.

        The simulator waits only for plans that answer a world version (or a constraints version),
        so those reach it at a fixed site time. A plan made between two versions - on a robot
        acknowledging its command, or starting to wait at a door - would reach it at a moment that
        depends on the machine's load, and the same seed would not give the same mission. Such news
        is kept and planned for with the next version."""
        if not self._lockstep():
            return False
        return not any(reason.partition(":")[0] in LOCKSTEP_TRIGGERS for reason in self._dirty)

    # ------------------------------------------------------------------ inputs

    def _note_version(self, version: int) -> None:
        if version > self.world_version:
            self.world_version = version
            self.trigger("world_version")

    def on_clock(self, msg: Clock, _key: str) -> None:
        """When the simulator stands still, at which version (see _repeat_plan) and what for."""
        self._sim_clock = msg
        self._note_version(msg.world_version)
        if not msg.paused:
            self._paused = None
            return
        where = (msg.world_version, msg.time)
        paused = self._paused
        if paused is None or paused[0] != where:
            self._paused = (where, time.monotonic())
        self._plan_if_awaited()

    def on_pose(self, msg: RobotPose, _key: str) -> None:
        if msg.robot not in self.site.robots:
            self.counters["unknown_robot"] += 1
            return
        self.poses[msg.robot] = (msg.x, msg.y, msg.theta)
        if self._lockstep():
            return  # poses between two world versions fall at wall-clock moments: checked at plan time instead
        if self._off_track(msg.robot):
            last = self._off_track_at.get(msg.robot, -math.inf)
            if time.monotonic() - last >= OFF_TRACK_COOLDOWN:
                self._off_track_at[msg.robot] = time.monotonic()
                self._force.add(msg.robot)
                self.counters["off_track"] += 1
                self.trigger(f"off_track:{msg.robot}")

    def _off_track(self, robot: str) -> bool:
        """Whether ``robot`` is moving along the trajectory sent to it but far from it."""
        sent = self.dispatcher.current.get(robot)
        status = self.statuses.get(robot)
        pose = self.poses.get(robot)
        if (
            pose is None
            or sent is None
            or len(sent.trajectory) < 2
            or status is None
            or status.state != "moving"
            or status.action_id != sent.action_id
        ):
            return False
        return polyline_distance(pose[:2], sent.trajectory) > self.settings.off_track

    def _force_off_track(self) -> None:
        """Lockstep: the robots far off their trajectories at this world version (their poses of
        this instant came just before the clock) get a fresh command with the plan."""
        for robot in sorted(self.site.robots):
            if robot not in self._force and self._off_track(robot):
                self._force.add(robot)
                self.counters["off_track"] += 1

    def on_status(self, msg: RobotStatus, _key: str) -> None:
        if msg.robot not in self.site.robots:
            self.counters["unknown_robot"] += 1
            return
        before = self.statuses.get(msg.robot)
        self.statuses[msg.robot] = msg
        self.dispatcher.note_reported_id(msg.robot, msg.action_id)
        self._adopt(msg)
        self._note_version(msg.world_version)
        sent = self.dispatcher.current.get(msg.robot)
        changed = before is None or (
            before.state,
            before.action_id,
            tuple(before.carrying),
            tuple(before.delivered),
        ) != (msg.state, msg.action_id, tuple(msg.carrying), tuple(msg.delivered))
        if sent is not None and msg.action_id == sent.action_id and msg.state in FINISHED_STATES:
            self._finished.add(msg.robot)
        if sent is not None and msg.action_id < sent.action_id:
            self._resend(msg.robot)
        if changed:
            self.trigger(f"status:{msg.robot}:{msg.state}")

    def _adopt(self, msg: RobotStatus) -> None:
        """Take a robot's running action as the one sent, when this planner sent it nothing (a
        restart): a plan whose front is that action then leaves it running (same id, not sent
        again), and a load or unload under way counts as in progress."""
        if msg.robot in self.dispatcher.current or msg.action_id <= 0 or msg.state in FINISHED_STATES:
            return
        if msg.action in ("", "stop"):
            return
        self.dispatcher.current[msg.robot] = Dispatched(msg.action, tuple(msg.args), msg.action_id, msg.plan_id, [])
        self.counters["actions_adopted"] += 1
        self.log.info(
            "%s is executing action %d (%s %s) of an earlier plan: taken over",
            msg.robot,
            msg.action_id,
            msg.action,
            " ".join(msg.args),
        )

    def _resend(self, robot: str) -> None:
        """Send the robot's current command again (same id) when its status shows an older action.

        A command published before the robot (or the simulator) subscribed is lost, and a replan
        that keeps the same front action does not send it again, so a lockstep simulator would wait
        for it forever. Statuses come at least once a wall second, so a lost command is sent again
        within about a second; one that did arrive is ignored as a duplicate (same id). A command
        younger than RESEND_INTERVAL is left alone: the status may have been sent before it arrived."""
        now = time.monotonic()
        if now - self._sent_at.get(robot, -math.inf) < RESEND_INTERVAL:
            return
        cmd = self.dispatcher.resend(robot)
        if cmd is None:
            return
        self._sent_at[robot] = now
        self.counters["commands_resent"] += 1
        self.log.debug(
            "sending %s's command %d (%s) again: its status shows action %d",
            robot,
            cmd.action_id,
            cmd.action,
            self.statuses[robot].action_id,
        )
        self.publish(self.keys.robot_command(robot), cmd)

    def on_door(self, msg: DoorState, _key: str) -> None:
        if msg.door not in self.site.openings:
            self.counters["unknown_door"] += 1
            return
        before = self.doors.get(msg.door)
        self.doors[msg.door] = msg
        self._note_version(msg.world_version)
        opening = self.site.openings[msg.door]
        if opening.human_operated and (before is None or before.open != msg.open):
            self.trigger(f"door:{msg.door}:{'open' if msg.open else 'closed'}")

    def on_constraints(self, msg: ConstraintSet, _key: str) -> None:
        if self.constraint_set is not None and msg.version <= self.constraint_set.version:
            return
        self.constraint_set = msg
        program = ConstraintProgram.build(from_constraint_set(msg))
        for cid, why in sorted(program.invalid.items()):
            self.log.warning("constraint %s is left out: %s", cid, why)
        if program.invalid:
            self.publish_conflict(
                sorted(program.invalid),
                "invalid: " + "; ".join(f"{c}: {w}" for c, w in sorted(program.invalid.items())),
            )
        self.constraints = program if program.active else None
        self.trigger(f"constraints:v{msg.version}")
        self._plan_if_awaited()

    def on_event(self, msg: Event, _key: str) -> None:
        if msg.kind in ("action_done", "action_failed") and msg.robot in self.site.robots:
            data = msg.data if isinstance(msg.data, dict) else {}
            # The pose that goes with the event travels in it: poses come on another key, which may
            # be delivered later than the event.
            pose = data.get("pose")
            if (
                isinstance(pose, list)
                and len(pose) == 3
                and all(isinstance(v, (int, float)) and math.isfinite(v) for v in pose)
            ):
                self.poses[msg.robot] = (float(pose[0]), float(pose[1]), float(pose[2]))
            sent = self.dispatcher.current.get(msg.robot)
            if sent is not None and data.get("action_id") == sent.action_id:
                self._finished.add(msg.robot)
            self.trigger(f"{msg.kind}:{msg.robot}")

    # ------------------------------------------------------------------ replanning

    def tick(self) -> None:
        # (The world version is noted in on_clock, in order with the statuses and events before it.)
        if not self._dirty or (self._lockstep() and not self._version_complete()):
            self._repeat_plan()
            return
        now = time.monotonic()
        if now - self._last_trigger < SETTLE and now - self._first_trigger < MAX_DELAY:
            return
        self._plan_now(now)

    def _lockstep(self) -> bool:
        return isinstance(self.clock, SimClock) and self.clock.mode == "lockstep"

    def _version_complete(self) -> bool:
        """Lockstep: whether everything the plan for the current world version must answer is in.

        A version's statuses and events come before its clock, so until that clock has arrived a
        plan would start from whatever part of the version had arrived by then (which depends on
        the machine's load). While the simulator awaits the ack of the human's feedback, the ack
        brings a ConstraintSet the plan must answer; and a clock awaiting a constraints version
        this planner has not received yet waits for it too."""
        clock = self._sim_clock
        if clock is None or clock.world_version < self.world_version:
            return False
        if clock.paused and clock.awaiting == "feedback":
            return False
        have = self.constraint_set.version if self.constraint_set is not None else 0
        return have >= clock.constraints_version

    def _awaiting(self, what: str) -> Clock | None:
        """The simulator's clock when it is paused in lockstep at the world version known here,
        waiting for ``what`` (Clock.awaiting); else None."""
        clock = self._sim_clock
        if clock is None or clock.mode != "lockstep" or not clock.paused or clock.awaiting != what:
            return None
        return clock if clock.world_version == self.world_version else None

    def _plan_if_awaited(self) -> None:
        """Plan at once when a lockstep simulator waits for a plan newer than the one published and
        the news it waits on is in: its world version (statuses and events come before the clock)
        and the constraints version its accepted feedback made."""
        clock = self._awaiting("plan")
        if clock is None or not self._dirty:
            return
        have = self.constraint_set.version if self.constraint_set is not None else 0
        if have < clock.constraints_version:
            return  # on_constraints calls again
        sent = self.message
        if (
            sent is not None
            and sent.world_version >= clock.world_version
            and sent.constraints_version >= clock.constraints_version
        ):
            return  # answered already: what is pending now waits for the next version
        if self._plan_now(time.monotonic()):
            self.counters["plans_on_pause"] += 1

    def _plan_now(self, now: float) -> bool:
        """Plan for the pending news unless it must wait; whether it planned."""
        if not self._world_heard(now):
            return False  # the triggers stay pending
        if self._hold_for_world_version():
            self._held = True
            self._repeat_plan()
            return False
        if self._lockstep():
            self._force_off_track()
        reasons = sorted(self._dirty)
        self._dirty.clear()
        try:
            self.replan(reasons)
        except Exception as exc:
            self._answer_despite(exc)
        return True

    def _answer_despite(self, exc: Exception) -> None:
        """A replan that raised: say so, and still answer the world version with the plan being
        executed (no new commands) - a lockstep simulator waits for that answer, and the next news
        is planned afresh."""
        self.counters["planning_errors"] += 1
        self.log.exception("planning for world v%d failed: %s", self.world_version, exc)
        try:
            self.publish_plan(self.world(), None, f"planning failed: {type(exc).__name__}: {exc}")
        except Exception:
            self.log.exception("could not publish the plan being executed either")

    def _repeat_plan(self) -> None:
        """Publish the current plan again while the simulator stays paused at a world version it
        answers: the simulator may never have got it (module docstring)."""
        paused, message = self._paused, self.message
        if paused is None or message is None:
            return
        (version, _), since = paused
        now = time.monotonic()
        if message.world_version < version or now - max(since, self._repeated_at) < REPEAT_AFTER:
            return
        first = self._repeated_at < since  # the first repeat in this pause is worth a line; later ones are not
        self._repeated_at = now
        self.counters["plans_repeated"] += 1
        self.log.log(
            logging.INFO if first else logging.DEBUG,
            "the simulator has been paused at world v%d for %.0f s: publishing plan %d again (in case it was lost)",
            version,
            now - since,
            message.plan_id,
        )
        self.publish(self.keys.plan(), message)

    def _world_heard(self, now: float) -> bool:
        """Whether the planner knows enough of the robots to plan (see the module docstring)."""
        if isinstance(self.clock, SimClock) and not self.clock.synced:
            return False  # the simulator's clock is the site's time: nothing to plan before it ticks
        missing = [rid for rid in self.site.robots if rid not in self.poses or rid not in self.statuses]
        if not missing:
            if self._state_wait_since is not None:
                self.log.info("every robot's pose and status in after %.1f s: planning", now - self._state_wait_since)
                self._state_wait_since = None
            return True
        clock_version = getattr(self.clock, "world_version", 0)
        if not self.statuses and not clock_version:
            # Nothing from any robot: a fresh mission plans from the site's start, once a running
            # one has had the time to be heard.
            return now - self._started_at >= START_GRACE
        if self._state_wait_since is None:
            self._state_wait_since = now
            self._state_wait_reported = False
            self.log.info(
                "a mission is under way (world v%d): waiting for the pose and status of %s before planning",
                max(self.world_version, clock_version),
                ", ".join(missing),
            )
        if now - self._state_wait_since < STATE_WAIT:
            return False
        if not self._state_wait_reported:
            self._state_wait_reported = True
            self.log.warning(
                "planning without the pose or status of %s (nothing from them in %.0f s)",
                ", ".join(missing),
                STATE_WAIT,
            )
        return True

    def world(self) -> World:
        now = self.clock.now()
        hold = self.site.params.door_hold_time
        robots: dict[str, RobotState] = {}
        for rid, spec in self.site.robots.items():
            pose = self.poses.get(rid, spec.start)
            status = self.statuses.get(rid)
            if status is None:
                robots[rid] = RobotState(id=rid, pose=pose)
                continue
            robots[rid] = RobotState(
                id=rid,
                pose=pose,
                carrying=frozenset(o for o in status.carrying if o in self.site.objects),
                delivered=frozenset(o for o in status.delivered if o in self.site.objects),
                beside=self._beside(status),
                in_progress=self._in_progress(rid, status, pose, now),
            )
        open_doors = {}
        for did, ds in self.doors.items():
            opening = self.site.openings.get(did)
            if ds.open and opening is not None and opening.human_operated:
                open_doors[did] = ds.until - hold if ds.until > 0 else ds.stamp
        return World(now=now, robots=robots, open_doors=open_doors)

    def _beside(self, status: RobotStatus) -> str:
        """The opening a robot stands beside: the door it waits at, or the one its last action
        (approach or opendoor, now over) brought it to."""
        if status.state == "waiting_at_door" and status.waiting_door in self.site.openings:
            return status.waiting_door
        if (
            status.state in ("done", "idle")
            and status.action in ("approach", "opendoor")
            and status.args
            and status.args[0] in self.site.openings
        ):
            return status.args[0]
        return ""

    def _in_progress(
        self, rid: str, status: RobotStatus, pose: tuple[float, float, float], now: float
    ) -> InProgress | None:
        """Actions that must be finished first: a gothrough while in the doorway, a load/unload in place."""
        sent = self.dispatcher.current.get(rid)
        if sent is None or status.action_id != sent.action_id or not status.args:
            return None
        if status.state in ("loading", "unloading") and status.action in ("load", "unload"):
            left = max(1.0 - status.progress, 0.0) * self.site.params.load_time
            return InProgress(status.action, tuple(status.args[:1]), now + left)
        if status.state == "moving" and status.action == "gothrough" and status.args[0] in self.site.openings:
            opening = self.site.openings[status.args[0]]
            depth = self.planner.builder.beside_distance
            if math.dist((pose[0], pose[1]), opening.center) < depth * 0.9 and len(sent.trajectory) >= 2:
                end = sent.trajectory[-1]
                target = self.site.room_at(end[1], end[2])
                if target is not None and target.id in opening.rooms:
                    return InProgress("gothrough", (opening.id,), now, target.id)
        return None

    def replan(self, reasons: list[str]) -> None:
        world = self.world()
        continued = self.continued(reasons, world)
        if continued is not None:
            self.log.debug("plan followed at %.1f (world v%d): %s", world.now, self.world_version, ", ".join(reasons))
            self.result = continued
            self.counters["plans"] += 1
            self.counters["plans_continued"] += 1
            self.publish_plan(world, continued, "")
            return
        self.log.debug("replanning at %.1f (world v%d): %s", world.now, self.world_version, ", ".join(reasons))
        result = self.planner.plan(world, self.constraints, self.settings.method, warm=self.result)
        if result.status == "conflict":
            self.publish_conflict(result.conflict_ids, result.diagnostic)
            fallback = self.planner.plan(world, self.valid_constraints, self.settings.method, warm=self.result)
            if fallback.status in ("ok", "timeout"):
                fallback.diagnostic = f"{result.diagnostic}; planned with the last constraint set that worked"
                result = fallback
        elif result.status in ("ok", "timeout"):
            self.valid_constraints = self.constraints
        if result.status in ("ok", "timeout"):
            self.result = result
            self.counters["plans"] += 1
        else:
            self.counters["planning_failures"] += 1
            self.log.warning("no new plan (%s): %s", result.status, result.diagnostic)
        self.publish_plan(world, result if result.status in ("ok", "timeout") else None, result.diagnostic)

    def continued(self, reasons: list[str], world: World) -> TeamResult | None:
        """The plan being executed, moved past the actions that just ended, when that is all that
        happened; None when the task planner must run.

        Most triggers are a robot ending its front action. When it ends no more than
        CONTINUE_TOLERANCE after the plan's time for it, re-solving would retime the plans by little
        and start the IIDP rounds from the same team, so the plan is kept as it is (Algorithm 1's P^t
        call on an unchanged problem). An action often ends well before its planned end: robots
        start their next action as soon as the last one ends, without the waits the plan allows for
        (beside a passage another robot was planned to use, say), so they run ahead of the plan; the
        plan still holds for them - their stops, orders and the openings they use - and what
        running ahead changes shows as news of its own (a robot waiting at a closed door). A world
        version with none of this (a robot-operated door opening) changes nothing the planner
        reads. Anything else - constraints, a human-operated door opening or closing, a failure, a
        robot waiting at a door or off its trajectory, an action ending late - is solved anew."""
        kept = self.result
        if kept is None or kept.status not in ("ok", "timeout") or kept.conflicts:
            return None
        ended: set[str] = set()
        for reason in reasons:
            kind, _, rest = reason.partition(":")
            if kind == "world_version":
                continue
            if kind == "status" and rest.rpartition(":")[2] in ROUTINE_STATES:
                continue
            if kind == "action_done":
                ended.add(rest)
                continue
            return None
        if not ended <= self._finished or self._force:
            return None  # an end of an action not the one sent, or a robot to re-command
        plans = dict(kept.plans)
        for rid in sorted(self._finished):
            sent = self.dispatcher.current.get(rid)
            index = self.dispatcher.front_index.get(rid)
            plan = plans.get(rid)
            if sent is None or index is None or plan is None or index >= len(plan.steps):
                return None
            step = plan.steps[index]
            if (step.action, step.args) != (sent.action, sent.args):
                return None
            if world.now - kept.absolute(step.end) > CONTINUE_TOLERANCE:
                return None  # late: the others' plans may count on it
            plans[rid] = replace(plan, steps=plan.steps[index + 1 :])
        base = int(math.floor(world.now))
        delta = kept.base - base
        return replace(
            kept,
            base=base,
            plans={rid: plan.shifted(delta) for rid, plan in plans.items()},
            existing=frozenset(self.planner.existing_windows(world, base)),
            iterations=0,
            solve_time=0.0,
            solves=0,
            diagnostic="",
        )

    def publish_plan(self, world: World, result: TeamResult | None, diagnostic: str) -> None:
        """Publish the TeamPlan (the new one, or the kept one re-stamped) and the commands."""
        self.plan_id += 1
        cs_version = self.constraint_set.version if self.constraint_set is not None else 0
        kept = self.result
        if kept is None:
            self.message = TeamPlan(
                plan_id=self.plan_id,
                world_version=self.world_version,
                constraints_version=cs_version,
                method=self.settings.method,
                diagnostic=diagnostic[:4096],
            )
            self.publish(self.keys.plan(), self.message)
            return
        finished, force = set(self._finished), set(self._force)
        self._finished.clear()
        self._force.clear()
        commands, front = (
            self.dispatcher.dispatch(kept, world, self.plan_id, finished=finished, force=force)
            if result is not None
            else ([], {})
        )
        if result is None:
            front = {rid: d.action_id for rid, d in self.dispatcher.current.items()}
        else:
            kept = self.result = self.dispatcher.with_waits(kept)  # the plan's times include the waits
        # Commands first: a simulator in lockstep waits for the commands a plan names before it runs on.
        for cmd in commands:
            self.publish(self.keys.robot_command(cmd.robot), cmd)
            self._sent_at[cmd.robot] = time.monotonic()
        for intent in self.dispatcher.intents(self.plan_id):
            # (an action taken over from before a restart has no trajectory to show)
            if intent.robot in kept.plans and not kept.plans[intent.robot].empty and intent.trajectory:
                self.publish(self.keys.intent(intent.robot), intent)
        self.message = to_message(
            kept, self.plan_id, self.world_version, cs_version, front, diagnostic, self.dispatcher.front_index
        )
        self.publish(self.keys.plan(), self.message)
        self.log.info(
            "plan %d for world v%d, constraints v%d: makespan %d s, %d door openings, %d rounds, %.2f s%s",
            self.plan_id,
            self.world_version,
            cs_version,
            kept.makespan,
            kept.door_openings,
            kept.iterations,
            kept.solve_time,
            f" ({diagnostic})" if diagnostic else "",
        )

    def publish_conflict(self, ids: list[str], reason: str) -> None:
        version = self.constraint_set.version if self.constraint_set is not None else 0
        key = (version, tuple(ids))
        if key in self.reported_conflicts:
            return
        self.reported_conflicts.add(key)
        self.counters["plan_conflicts"] += 1
        self.log.warning("constraints %s: %s", ", ".join(ids) or "(none)", reason)
        self.publish(
            self.keys.event(),
            Event(
                kind="plan_conflict",
                data={"constraints": list(ids), "constraints_version": version, "reason": reason[:1000]},
            ),
        )


def to_message(
    result: TeamResult,
    plan_id: int,
    world_version: int,
    constraints_version: int,
    front: dict[str, int],
    diagnostic: str,
    skip: dict[str, int] | None = None,
) -> TeamPlan:
    """``skip``: leading steps of a robot's plan that need not be executed (an opendoor of a door
    open now, see :meth:`Dispatcher.front`); the message starts at the step dispatched."""
    robots = {}
    for rid, plan in sorted(result.plans.items()):
        steps = []
        for i, s in enumerate(plan.steps[(skip or {}).get(rid, 0) :]):
            steps.append(
                PlanStep(
                    action=s.action,
                    args=list(s.args),
                    start=float(result.absolute(s.start)),
                    end=float(result.absolute(s.end)),
                    action_id=front.get(rid, 0) if i == 0 else 0,
                )
            )
        robots[rid] = steps
    openings = [
        PlannedOpening(
            door=o.door, start=float(result.absolute(o.start)), end=float(result.absolute(o.end)), robots=list(o.robots)
        )
        for o in result.openings
    ]
    return TeamPlan(
        plan_id=plan_id,
        world_version=world_version,
        constraints_version=constraints_version,
        method=result.method,
        makespan=float(result.makespan),
        door_openings=result.door_openings,
        solve_time=round(result.solve_time, 4),
        iterations=result.iterations,
        robots=robots,
        openings=openings,
        diagnostic=diagnostic[:4096],
    )
