"""The planner service: keeps the world, plans, dispatches front actions, replans (Algorithm 1).

Inputs: robot poses and statuses, door states, the ConstraintSet, events (action done/failed) and
the clock (its ``world_version``). Outputs (:mod:`.outputs`): the TeamPlan on ``plan`` (also served to
late joiners), each robot's RobotCommand for its front action and its Intent, ``plan_conflict`` events.

This class only wires the parts together: typed triggers (:mod:`.triggers`) for every input that may
call for a plan; the :class:`~.scheduler.ReplanScheduler` (one replan for a burst); the
:class:`~.world_cache.WorldCache`; the :class:`~.lockstep.LockstepFollower` (when a lockstep
simulator has all of a version and waits for a plan: planning only then makes a lockstep mission the
same on a busy machine as on an idle one; and what to do when it waits for one not being made; the
rules are :mod:`runtime.lockstep`);
:class:`~.readiness.Readiness` (enough known to plan after a (re)start); :func:`~.continuation.continued`
(the plan being executed kept when the news calls for no solve). Every world version is answered
with a TeamPlan, even if nothing changed. Replanning starts from the plan being executed (IIDP warm
start). When the constraints leave a robot no plan, ``plan_conflict`` names the conflicting ones and
planning goes on with the last set that worked. After a restart, the actions robots are executing
(their statuses name them) are taken over as the ones sent.
"""

from __future__ import annotations

import time

from protocol.events import RobotOutcome
from protocol.messages import Clock, ConstraintSet, DoorState, Event, RobotPose, RobotStatus
from protocol.site import Site
from runtime.clock import SimClock, WallClock
from runtime.lockstep import in_lockstep
from runtime.service import Service
from runtime.transport import ZenohOptions

from .constraints import ConstraintProgram, from_constraint_set
from .continuation import continued
from .dispatcher import FINISHED_STATES, Dispatcher
from .lockstep import LockstepFollower, Stall
from .off_track import OffTrackWatch
from .outputs import PlanOutputs, adopted
from .plan import TeamResult
from .planner import TaskPlanner
from .readiness import Readiness
from .scheduler import ReplanScheduler
from .settings import ServiceSettings
from .teammotion import TeamMotion
from .triggers import ActionEnded, DoorChanged, NewConstraints, NewWorldVersion, OffTrack, Start, StatusChanged, Trigger
from .world import World
from .world_cache import WorldCache


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
        self.cache = WorldCache(site, self.planner.builder.beside_distance)
        self.scheduler = ReplanScheduler()
        self.lockstep = LockstepFollower()
        self.readiness = Readiness(time.monotonic(), self.log)
        self.constraint_set: ConstraintSet | None = None
        self.constraints: ConstraintProgram | None = None
        self.valid_constraints: ConstraintProgram | None = None  # the last set that left a plan
        self.result: TeamResult | None = None
        self.outputs = PlanOutputs(self.publish, self.keys, self.dispatcher, self.settings.method, self.count, self.log)
        self._finished: set[str] = set()  # robots whose sent action is reported over
        self.off_track = OffTrackWatch()

    @property
    def world_version(self) -> int:
        return self.cache.world_version

    @property
    def constraints_version(self) -> int:
        return self.constraint_set.version if self.constraint_set is not None else 0

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
        # What was last published, for a lockstep simulator that waited in vain for it: its plan, and
        # the command each robot is on (a publication that never arrived is asked for again).
        self.serve(k.plan(), lambda _query: self.outputs.message)
        self.serve_each(
            k.robot_command(), lambda _query: [(k.robot_command(c.robot), c) for c in self.dispatcher.sent_commands()]
        )
        self.every(0.02, self.tick)
        self._fetch_constraints()  # a restarted planner picks up the active constraints at once
        self.trigger(Start())

    def _fetch_constraints(self) -> None:
        """Ask the restrictor for the active ConstraintSet (none there yet: it comes by pub/sub)."""
        try:
            for cs in self.query(self.keys.constraints(), ConstraintSet, timeout=1.0):
                self.on_constraints(cs, self.keys.constraints())
        except Exception as exc:
            self.log.debug("no constraints to fetch: %s", exc)

    def trigger(self, trigger: Trigger) -> None:
        self.scheduler.add(trigger, time.monotonic())

    # ------------------------------------------------------------------ inputs

    def _note_version(self, version: int) -> None:
        if self.cache.note_version(version):
            self.trigger(NewWorldVersion())

    def on_clock(self, msg: Clock, _key: str) -> None:
        self.lockstep.on_clock(msg, time.monotonic())
        self._note_version(msg.world_version)
        if msg.paused:
            self._plan_if_awaited()

    def on_pose(self, msg: RobotPose, _key: str) -> None:
        if msg.robot not in self.site.robots:
            self.counters["unknown_robot"] += 1
            return
        self.cache.poses[msg.robot] = (msg.x, msg.y, msg.theta)
        if self._lockstep():
            return  # poses between two world versions fall at wall-clock moments: checked at plan time instead
        if self.off_track.notice(msg.robot, self._off_track(msg.robot), time.monotonic()):
            self.counters["off_track"] += 1
            self.trigger(OffTrack(msg.robot))

    def _off_track(self, robot: str) -> bool:
        return self.cache.off_track(robot, self.dispatcher.current.get(robot), self.settings.off_track)

    def _force_off_track(self) -> None:
        """Lockstep: the robots far off their trajectories at this world version (their poses of
        this instant came just before the clock) get a fresh command with the plan."""
        added = self.off_track.sweep(sorted(self.site.robots), self._off_track)
        if added:
            self.counters["off_track"] += added

    def on_status(self, msg: RobotStatus, _key: str) -> None:
        if msg.robot not in self.site.robots:
            self.counters["unknown_robot"] += 1
            return
        changed = self.cache.set_status(msg)
        self.dispatcher.note_reported_id(msg.robot, msg.action_id)
        self._adopt(msg)
        self._note_version(msg.world_version)
        sent = self.dispatcher.current.get(msg.robot)
        if sent is not None and msg.action_id == sent.action_id and msg.state in FINISHED_STATES:
            self._finished.add(msg.robot)
        if sent is not None and msg.action_id < sent.action_id:
            self.outputs.resend(msg)
        if changed:
            self.trigger(StatusChanged(msg.robot, msg.state))

    def _adopt(self, msg: RobotStatus) -> None:
        """Take over the action a robot runs from before a restart (see :func:`.outputs.adopted`)."""
        taken = adopted(msg, self.dispatcher.current, FINISHED_STATES)
        if taken is None:
            return
        self.dispatcher.current[msg.robot] = taken
        self.counters["actions_adopted"] += 1
        action = " ".join([msg.action, *msg.args])
        self.log.info("%s is executing action %d (%s) of an earlier plan: taken over", msg.robot, msg.action_id, action)

    def on_door(self, msg: DoorState, _key: str) -> None:
        if msg.door not in self.site.openings:
            self.counters["unknown_door"] += 1
            return
        changed = self.cache.set_door(msg)
        self._note_version(msg.world_version)
        if changed:
            self.trigger(DoorChanged(msg.door, msg.open))

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
        self.trigger(NewConstraints(msg.version))
        self._plan_if_awaited()
        self.tick()  # urgent: not at the next tick

    def on_event(self, msg: Event, _key: str) -> None:
        if msg.kind in ("action_done", "action_failed") and msg.robot in self.site.robots:
            data = msg.data
            assert isinstance(data, RobotOutcome)  # the Event's kind says so
            # The pose that goes with the event travels in it: poses come on another key, which may
            # be delivered later than the event.
            self.cache.set_pose_from(msg.robot, data.pose)
            sent = self.dispatcher.current.get(msg.robot)
            if sent is not None and data.action_id == sent.action_id:
                self._finished.add(msg.robot)
            self.trigger(ActionEnded(msg.robot, failed=msg.kind == "action_failed"))

    # ------------------------------------------------------------------ when to plan

    def tick(self) -> None:
        # (The world version is noted in on_clock, in order with the statuses and events before it.)
        stall = self.lockstep.stall(self.outputs.message, self.constraints_version, time.monotonic())
        if stall is not None:
            self._recover(stall)
        if not self.scheduler or (
            self._lockstep() and not self.lockstep.version_complete(self.world_version, self.constraints_version)
        ):
            self._repeat_plan()
            return
        now = time.monotonic()
        if self.scheduler.settled(now):
            self._plan_now(now)

    def _recover(self, stall: Stall) -> None:
        """The lockstep simulator waits for a plan not being made (lockstep.py: Stall)."""
        if stall.report:
            held = (self.world_version, self.constraints_version, self.scheduler.pending, self.cache.missing())
            self.log.warning("%s", stall.describe(*held))
        if stall.fetch_constraints:
            self.count("stall_constraints_fetched")
            self._fetch_constraints()
        if not self.scheduler and stall.world_version == self.world_version:
            self.count("stall_replans")  # news whose trigger was lost: answer the version anyway
            self.trigger(NewWorldVersion())

    def _lockstep(self) -> bool:
        return in_lockstep(self.clock)

    def _plan_if_awaited(self) -> None:
        """Plan at once when a lockstep simulator waits for a plan newer than the one published and
        the news it waits on is in (statuses and events of its version come before the clock)."""
        if not self.scheduler or not self.lockstep.plan_awaited(
            self.world_version, self.constraints_version, self.outputs.message
        ):
            return
        if self._plan_now(time.monotonic()):
            self.counters["plans_on_pause"] += 1

    def _plan_now(self, now: float) -> bool:
        """Plan for the pending news unless it must wait; whether it planned."""
        if not self._ready(now):
            return False  # the triggers stay pending
        if self._lockstep() and self.scheduler.answers_nothing_awaited():
            self.scheduler.hold()  # planned with the next world version
            self._repeat_plan()
            return False
        if self._lockstep():
            self._force_off_track()
        triggers = self.scheduler.take()
        try:
            self.replan(triggers)
        except Exception as exc:
            self._answer_despite(exc)
        return True

    def _ready(self, now: float) -> bool:
        return self.readiness.ready(
            now,
            clock_synced=not isinstance(self.clock, SimClock) or self.clock.synced,
            missing=self.cache.missing(),
            heard_any=bool(self.cache.statuses),
            clock_version=getattr(self.clock, "world_version", 0),
            world_version=self.world_version,
        )

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
        answers: the simulator may never have got it."""
        repeat = self.lockstep.repeat_due(self.outputs.message, time.monotonic())
        if repeat is not None:
            self.outputs.repeat(repeat)

    # ------------------------------------------------------------------ planning

    def world(self) -> World:
        return self.cache.snapshot(self.clock.now(), self.dispatcher.current)

    def replan(self, triggers: list[Trigger]) -> None:
        world = self.world()
        reasons = ", ".join(map(str, triggers))
        kept = continued(
            self.result,
            triggers,
            finished=self._finished,
            force=self.off_track.force,
            sent=self.dispatcher.current,
            front_index=self.dispatcher.front_index,
            now=world.now,
            existing=lambda base: frozenset(self.planner.existing_windows(world, base)),
        )
        if kept is not None:
            self.log.debug("plan followed at %.1f (world v%d): %s", world.now, self.world_version, reasons)
            self.result = kept
            self.counters["plans"] += 1
            self.counters["plans_continued"] += 1
            self.publish_plan(world, kept, "")
            return
        self.log.debug("replanning at %.1f (world v%d): %s", world.now, self.world_version, reasons)
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

    def publish_plan(self, world: World, result: TeamResult | None, diagnostic: str) -> None:
        """Publish the TeamPlan (the new one, or the kept one re-stamped) and the commands."""
        finished, force = set(self._finished), set(self.off_track.force)
        if self.result is not None:
            self._finished.clear()
            self.off_track.take()
        versions = (self.world_version, self.constraints_version)
        kept = self.outputs.plan(world, self.result, result is not None, diagnostic, versions, finished, force)
        if kept is not None:
            self.result = kept  # with the waits team motion added to its times

    def publish_conflict(self, ids: list[str], reason: str) -> None:
        self.outputs.conflict(ids, reason, self.constraints_version)
