"""The ``arroch sim`` process: the engine on Zenoh, in one of the three clock modes.

Inputs: ``robot/*/command`` (RobotCommand), ``plan`` (TeamPlan, for lockstep), the restrictor's
acks of the human's feedback (queries on ``feedback``), in lockstep with a camera the AR
client's ``ar/<cid>/overlay`` (a held frame's overlay lets time go on: :class:`~.camfeed.FrameHold`),
``study/control`` (StudyControl: the experimenter pauses, resumes or aborts the trial), and with
``--human participant`` her ``participant/action`` (ParticipantAction), with ``--doors sensor`` the
real doors' ``door/<did>/sensor`` (DoorState). What cannot be taken (an act she cannot take now, a
sensor of a door that has none) is dropped, counted and logged at WARNING with the reason.
Outputs: ``clock``, ``robot/<rid>/pose``, ``robot/<rid>/status``, ``door/<did>/state``, ``event``,
``human/state`` (HumanState: on every change of her place, door, task or the pause, and once a wall
second), and with ``--camera`` the virtual tablet camera's ``camera/<cid>/frame`` and ``truth``.

Pause (StudyControl ``pause``): no step runs and the Clock says ``paused``; on ``resume`` the wall
pacer starts counting again from the paused instant, so site time goes on from there without a jump.
``abort`` ends the mission at once (``mission_done``, ``completed`` false, ``reason`` "aborted by the
experimenter: ..."); with ``--until-done`` the process then exits with :data:`EXIT_STUDY_ABORTED`.

Lockstep: time advances only while the handshake of :mod:`runtime.lockstep` allows it (this
process holds its gate, ``self.gate``; a held camera frame and real robots' drivers wait besides).

Order of publication after a tick that changed the world: poses, then statuses and door states,
then the events, then the clock. A planner woken by an event (or by the new ``world_version`` on
a status) has therefore already received the poses of that instant.

Publishing rates:
- poses every ``1/pose_rate`` of sim time (20 Hz by default) in every mode, lockstep included, so a
  recording or a viewer gets the same smooth track at any speed (the instants are site times, so
  they do not depend on the machine's load either), and always at a new world version, when the
  planner needs them. In lockstep with nobody watching (no live service but the mission's own loop,
  :data:`NOT_WATCHING`: a sweep's trial) only every ``1/SPARSE_POSE_RATE`` site s between world
  versions: the planner plans from a version's poses only, and the poses nobody reads cost a sweep
  trial about half its CPU time again;
- the clock with every pose batch, at every new world version, and twice a wall second while
  time stands still (paused in lockstep, or the mission over);
- statuses and door states when they change, and all of them once a wall second for late joiners
  (with every pose: while lockstep time stands still no pose batch is due, and a planner restarted
  then must still learn where the robots are). In lockstep that repetition happens only while time
  stands still, and every status goes out again at each new world version: a repetition between two
  versions would fall at a wall-clock moment, and the planner would plan from a status (a progress, a
  pose) that depends on the machine's load. A door state is stamped with the time its state last
  changed, however often it is repeated;
- events as they happen.

Everything runs on the service's worker thread (the Service base's loop); the only other thread
sends feedback queries (:mod:`services.sim.feedback`).
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import zenoh

from protocol.keys import chunk_at
from protocol.messages import (
    Clock,
    DoorState,
    Event,
    HumanState,
    Overlay,
    ParticipantAction,
    RobotCommand,
    RobotPose,
    StudyControl,
    TeamPlan,
)
from protocol.site.model import Site
from runtime.executor import status_message
from runtime.lockstep import COMMAND, OPEN, PLAN, LockstepGate, Wait, simulator_waits
from runtime.service import Service
from runtime.transport import ZenohOptions

from .camfeed import MAX_MISSED
from .engine import Engine, EngineConfig, FeedbackRequest, SimEvent
from .feedback import FeedbackSender
from .human import HumanConfig
from .pacing import WallPacer
from .participant import ACTS as SIM_ACTS

log = logging.getLogger("arroch.sim")

HEARTBEAT = 1.0  # wall s between republications of every status and door state
PAUSED_CLOCK = 0.5  # wall s between clock messages while time stands still
LOCKSTEP_BUDGET = 0.02  # wall s of stepping per turn of the loop in lockstep, so messages get in
STALL_WARNING = 10.0  # wall s paused on one reason before lockstep says so at WARNING level
# Wall s paused for a plan or a command before the planner is asked for what it last sent: it sends a
# plan again after 2 s, so by then its publications were lost on the way (one trial of a 216-trial
# sample hung so, a plan and all its repeats lost through Zenoh's shared memory, off since then).
REFETCH_AFTER = 5.0
REFETCH_TIMEOUT = 1.0  # wall s the query waits for the planner's answer
FEEDBACK_ABORT = 120.0  # lockstep: default wall s without an ack of the human's feedback before the run is aborted
EXIT_ABORTED = 3  # exit code of a lockstep run aborted for want of an answer (feedback ack)
EXIT_STUDY_ABORTED = 4  # exit code (--until-done) of a trial the experimenter aborted (StudyControl abort)
REFUSAL_LOG_INTERVAL = 60.0  # wall s between two WARNING lines about one door sensor's same fault
SPARSE_POSE_RATE = 1.0  # Hz of site time: lockstep poses between world versions when nobody watches
NOT_WATCHING = frozenset({"sim", "planner", "restrictor", "supervisor"})  # services that need no pose track


@dataclass
class SimOptions:
    method: str = "arroch"
    mode: str = "lockstep"  # realtime, rate, lockstep
    rate: float = 1.0  # sim seconds per wall second in rate mode; in lockstep at most that (0: as fast as it goes)
    seed: int = 0
    pose_rate: float = 20.0  # Hz
    until_done: bool = False
    metrics_out: str | None = None
    events_out: str | None = None
    engine: EngineConfig = field(default_factory=EngineConfig)
    human: HumanConfig = field(default_factory=HumanConfig)
    camera: Any = None  # a services.sim.camfeed.CameraOptions, or None
    lockstep_abort: float = (
        FEEDBACK_ABORT  # lockstep: wall s to wait for an answer (feedback ack) before failing the run
    )
    robots: str = "sim"  # "none": every robot is real, executed by its own driver (services/sim/ros2_base.py)
    ros2_bases: Any = None  # a runtime.ros2.config.Ros2Config: every robot is a simulated ROS 2 base
    human_mode: str = "simulated"  # "participant": a person on her tablet page plays the human
    doors: str = "sim"  # "sensor": the human-operated doors are real and follow door/<did>/sensor
    participant: str = ""  # take acts of this participant only ("" any)
    trial: str = ""  # take acts and controls of this trial only ("" any)

    def as_params(self) -> dict[str, Any]:
        return {
            "mode": self.mode,
            "rate": self.rate if self.mode == "rate" else (1.0 if self.mode == "realtime" else 0.0),
            "pose_rate": self.pose_rate,
        }


class EngineClock:
    """The site clock of the sim itself: the engine's time (stamps every message it sends)."""

    synced = True

    def __init__(self) -> None:
        self.engine: Engine | None = None

    def now(self) -> float:
        return self.engine.time if self.engine is not None else 0.0


class SimService(Service):
    def __init__(
        self, site: Site, options: SimOptions, zenoh_options: ZenohOptions, *, namespace: str | None = None
    ) -> None:
        clock = EngineClock()
        super().__init__("sim", namespace or site.name, zenoh_options, clock=clock)  # type: ignore[arg-type]
        self.site = site
        self.options = options
        self.engine = Engine(
            site,
            method=options.method,
            seed=options.seed,
            human=options.human,
            config=options.engine,
            human_mode=options.human_mode,
            door_sensors=options.doors == "sensor",
        )
        self.engine.metrics.params.update(options.as_params())
        clock.engine = self.engine
        self.gate = LockstepGate()
        if options.mode == "lockstep":
            # A cap only delays steps, never changes what happens in them: the mission stays the same.
            self.pacer = WallPacer(options.rate, options.engine.tick) if options.rate > 0 else None
        else:
            self.pacer = WallPacer(options.rate if options.mode == "rate" else 1.0, options.engine.tick)
        self._pose_period = 1.0 / options.pose_rate
        self._watchers: set[str] = set()  # live services (liveliness keys) that may watch the poses
        self._next_pose_sim = 0.0
        self._last_heartbeat = 0.0
        self._last_clock_wall = 0.0
        self._blocker = ""
        self._blocked_since = 0.0
        self._stall_reported = False
        self._refetched_at = 0.0  # wall time the planner was last asked for its plan and commands
        self._sender: FeedbackSender | None = None
        self._events_file: IO[str] | None = None
        self._started_wall = 0.0
        self._exit_at: float | None = None
        self._finished = False
        self._camera = None
        self.exit_code = 0  # run_service's exit code: EXIT_ABORTED when lockstep had to give up
        self._door_since: dict[str, float] = {}  # door -> site time its open/closed state last changed
        self._external = None
        self.paused = False  # the experimenter paused the trial: no step runs
        self._human_sent: tuple[str, str, bool, bool] | None = None  # the HumanState last published
        self._last_human_wall = 0.0
        self._refusals_logged: dict[str, float] = {}  # door sensor fault -> wall time of its last WARNING
        if options.robots == "none" or options.ros2_bases is not None:
            from .ros2_base import ExternalRobots

            self._external = ExternalRobots(
                self.engine, sorted(self.engine.robots), ros2=options.ros2_bases, lockstep=options.mode == "lockstep"
            )

    # ------------------------------------------------------------------ set-up

    def setup(self) -> None:
        if self.options.events_out:
            self._events_file = open(self.options.events_out, "w", encoding="utf-8")
        self.subscribe(self.keys.robot_command(), RobotCommand, self._on_command)
        self.subscribe(self.keys.plan(), TeamPlan, self._on_plan)
        self.subscribe(self.keys.study_control(), StudyControl, self._on_study_control)
        if self.options.human_mode == "participant":
            self.subscribe(self.keys.participant_action(), ParticipantAction, self._on_participant)
        if self.options.doors == "sensor":
            self.subscribe(self.keys.door_sensor(), DoorState, self._on_door_sensor)
        hc = self.options.human
        lockstep = self.options.mode == "lockstep"
        self._sender = FeedbackSender(
            self,
            timeout=hc.feedback_timeout,
            retries=hc.feedback_retries,
            abort_after=self.options.lockstep_abort if lockstep else None,
        )
        if self._external is not None:
            self._external.setup(self)
        if self.options.camera is not None:
            from .camfeed import CameraFeed  # pybullet only when a camera is asked for

            self._camera = CameraFeed(
                self.site, self.engine, self.options.camera, lockstep=self.options.mode == "lockstep"
            )
            if self._camera.hold is not None:
                self.subscribe(self.keys.overlay(self.options.camera.id), Overlay, self._on_overlay)
        if self.options.mode == "lockstep":
            # history=True: those up before the sim count too.
            self._declared.append(
                self.session.liveliness().declare_subscriber(
                    self.keys.liveliness("*", "*"), self._on_liveliness, history=True
                )
            )
        self._started_wall = time.monotonic()
        self.engine.start()
        self._publish_tick(force_poses=True)
        if self.options.mode == "lockstep":
            period = 0.001
        else:
            assert self.pacer is not None
            period = min(0.01, self.options.engine.tick / self.pacer.rate / 2.0)
        self.every(period, self._pump, first=0.0)
        log.info(
            "sim %s: method %s, mode %s%s, seed %d, %d robots, %d objects, human %s, doors %s",
            self.site.name,
            self.options.method,
            self.options.mode,
            f" x{self.options.rate:g}" if self.options.mode == "rate" or self.pacer is not None else "",
            self.options.seed,
            len(self.engine.robots),
            len(self.engine.objects.items),
            self.options.human_mode,
            self.options.doors,
        )

    def teardown(self) -> None:
        if self._sender is not None:
            self._sender.close()
        if self._camera is not None:
            self._camera.close()
        if self._events_file is not None:
            self._events_file.close()
            self._events_file = None

    # ------------------------------------------------------------------ inputs

    def _on_command(self, cmd: RobotCommand, key: str) -> None:
        keyed = chunk_at(key, 3)
        if keyed != cmd.robot:
            self.count("commands_refused")
            self.log.warning("command for robot %r arrived on %r's key: refused", cmd.robot, keyed)
            return
        result = self.engine.apply_command(cmd)
        self.count(f"commands_{result}")
        self._publish_tick(force_poses=False)

    def _on_plan(self, plan: TeamPlan, key: str) -> None:
        if self.gate.on_plan(plan):
            self.count("plans")
            self.engine.plan_seen(plan)
        else:
            self.count("plans_stale")

    def _refetch_plan(self, wall: float, blocker: str) -> None:
        """Ask the planner for the plan and the commands it last published, and take them as if they had
        arrived: the same messages, so what happens next does not depend on how they came."""
        self._refetched_at = wall
        self.count("plan_refetches")
        self.log.warning(
            "lockstep paused %.0f s at t=%.2f (%s): asking the planner for its plan and commands again",
            wall - self._blocked_since,
            self.engine.time,
            blocker,
        )
        try:
            plans = self.query(self.keys.plan(), TeamPlan, timeout=REFETCH_TIMEOUT)
            commands = self.query(self.keys.robot_command(), RobotCommand, timeout=REFETCH_TIMEOUT)
        except Exception as exc:  # a session closing under us: the next pause asks again
            self.log.warning("could not ask the planner: %s", exc)
            return
        for plan in plans:
            self._on_plan(plan, self.keys.plan())
        for cmd in commands:
            self._on_command(cmd, self.keys.robot_command(cmd.robot))

    def _on_participant(self, action: ParticipantAction, key: str) -> None:
        if action.act not in SIM_ACTS:
            self.count("participant_actions_other")  # views, puzzle moves, feedback...: for the recording
            return
        reason = self._not_this_trial(action.trial, required=True)
        if not reason and self.options.participant and action.participant != self.options.participant:
            reason = f"participant: {action.participant!r} is not this run's {self.options.participant!r}"
        reason = reason or self.engine.human_act(action.act, action.door)
        what = f"{action.participant} {action.act}{f' {action.door}' if action.door else ''}"
        if reason:
            self.count("participant_actions_refused")
            self.log.warning("participant action %s at t=%.2f refused: %s", what, self.engine.time, reason)
            return
        self.count("participant_actions")
        self.log.info("participant action %s at t=%.2f", what, self.engine.time)
        self._after_input()

    def _on_door_sensor(self, state: DoorState, key: str) -> None:
        keyed = chunk_at(key, 3)
        if keyed != state.door:
            reason = f"door: a report of {state.door!r} on {keyed!r}'s sensor key"
        else:
            reason = self.engine.door_sensor(state.door, state.open, state.by)
        if reason:
            self.count("door_sensor_refused")
            self._warn_limited(
                f"{keyed}:{reason}", "door sensor report on %s (open=%s) refused: %s", key, state.open, reason
            )
            return
        self.count("door_sensor_reports")
        self._after_input()

    def _on_study_control(self, control: StudyControl, key: str) -> None:
        # A control without a trial id is the console's to whatever runs: an abort is never lost for it.
        reason = self._not_this_trial(control.trial, required=False)
        if not reason and self.engine.done:
            reason = f"command: the mission is over (t={self.engine.time:.2f})"
        if not reason and control.command == "pause" and self.paused:
            reason = "command: pause, but the trial is paused already"
        if not reason and control.command == "resume" and not self.paused:
            reason = "command: resume, but the trial is not paused"
        if reason:
            self.count("study_control_refused")
            self.log.warning("study control %s refused: %s", control.command, reason)
            return
        self.count(f"study_{control.command}")
        wall = time.monotonic()
        if control.command == "pause":
            self.paused = True
            self.log.info("trial paused by the experimenter at t=%.2f%s", self.engine.time, _why(control.reason))
        elif control.command == "resume":
            self.paused = False
            if self.pacer is not None:
                self.pacer.resync(self.engine.time, wall)  # count from now: no jump, no sprint to catch up
            self.log.info("trial resumed at t=%.2f%s", self.engine.time, _why(control.reason))
        else:
            reason = f"aborted by the experimenter: {control.reason or 'no reason given'}"
            self.log.warning("trial %s at t=%.2f", reason, self.engine.time)
            self.paused = False
            self.engine.abort(reason)
            if self.options.until_done:
                self.exit_code = EXIT_STUDY_ABORTED
        self._after_input()
        self._publish_clock()

    def _not_this_trial(self, trial: str, *, required: bool) -> str:
        if not self.options.trial or trial == self.options.trial or (not trial and not required):
            return ""
        return f"trial: {trial!r} is not this run's {self.options.trial!r}"

    def _after_input(self) -> None:
        """Publish what an input changed between two ticks; end the run if it ended the mission."""
        self._publish_tick(force_poses=False)
        if self.engine.done and not self._finished:
            self._finish()

    def _warn_limited(self, fault: str, message: str, *args: Any) -> None:
        """WARNING once per ``fault`` per REFUSAL_LOG_INTERVAL (a sensor may repeat itself many times a second)."""
        wall = time.monotonic()
        last = self._refusals_logged.get(fault)
        if last is not None and wall - last < REFUSAL_LOG_INTERVAL:
            return
        if len(self._refusals_logged) > 256:
            self._refusals_logged.clear()  # bounded, whatever a peer sends
        self._refusals_logged[fault] = wall
        self.log.warning(message, *args)

    def _on_overlay(self, overlay: Overlay, key: str) -> None:
        hold = self._camera.hold if self._camera is not None else None
        if hold is None:
            return
        if hold.suspended:
            self.log.info("overlays of camera %s come again: frames are held for them again", overlay.camera)
        if hold.overlay(overlay.frame_seq, time.monotonic()):
            self.count("camera_holds_released")

    # ------------------------------------------------------------------ the loop

    def _pump(self) -> None:
        wall = time.monotonic()
        self._collect_feedback_answers()
        if self._exit_at is not None:
            if wall >= self._exit_at:
                self.stop()
            return
        if self.engine.done:
            self._paused_heartbeat(wall)
            self._human_heartbeat(wall)
            return
        if self.paused:
            self._paused_heartbeat(wall)
        elif self.options.mode == "lockstep":
            self._run_lockstep(wall)
        else:
            assert self.pacer is not None
            for _ in range(self.pacer.due(self.engine.time, wall)):
                if not self._tick(wall):
                    break
        if self._camera is not None:
            self._camera.maybe_render(self, wall)
        lockstep_running = self.options.mode == "lockstep" and not self._blocker and not self.paused
        if wall - self._last_heartbeat >= HEARTBEAT and not lockstep_running:
            self._last_heartbeat = wall
            self._publish_poses()
            self._publish_states(everything=True)
        self._human_heartbeat(wall)

    def _run_lockstep(self, wall: float) -> None:
        deadline = wall + LOCKSTEP_BUDGET
        capped = self.pacer.due(self.engine.time, wall) if self.pacer is not None else -1  # ticks allowed (-1: any)
        while True:
            self._camera_hold()
            blocker = self._blocked()
            if blocker:
                if blocker != self._blocker:
                    self.log.debug("t=%.2f paused: %s", self.engine.time, blocker)
                    self._blocker = blocker
                    self._blocked_since = wall
                    self._publish_clock()
                elif wall - self._blocked_since >= STALL_WARNING and not self._stall_reported:
                    # Usually a planner that is not running, or a command it never sent.
                    self.log.warning(
                        "lockstep stalled %.0f s at t=%.2f: %s", wall - self._blocked_since, self.engine.time, blocker
                    )
                    self._stall_reported = True
                refetch_due = wall - max(self._blocked_since, self._refetched_at) >= REFETCH_AFTER
                if refetch_due and self._gate_waits_for().awaiting in (PLAN, COMMAND):
                    self._refetch_plan(wall, blocker)
                self._paused_heartbeat(wall)
                return
            self._blocker = ""
            self._stall_reported = False
            if capped == 0:
                return
            capped -= 1
            if not self._tick(time.monotonic()) or time.monotonic() >= deadline:
                return

    def _tick(self, wall: float) -> bool:
        """One engine step and what it must publish. False when the world changed or ended (in
        lockstep: stop and let the planner answer)."""
        version = self.engine.world_version
        self.engine.step()
        for request in self.engine.take_feedback():
            self._send_feedback(request)
        changed = self.engine.world_version != version
        self._publish_tick(force_poses=changed)
        if self._external is not None:
            self._external.after_tick()  # the ROS 2 bases' odometry, after the door states it depends on
        if self.engine.done:
            self._finish()
            return False
        return not changed

    # ------------------------------------------------------------------ publishing

    def _on_liveliness(self, sample: Any) -> None:
        """Who is up (Zenoh's thread): a service outside the mission's own loop may watch the poses."""
        service, instance = str(sample.key_expr).split("/")[-2:]
        if service in NOT_WATCHING:
            return
        if sample.kind == zenoh.SampleKind.PUT:
            self._watchers.add(f"{service}/{instance}")
        else:
            self._watchers.discard(f"{service}/{instance}")

    def _publish_tick(self, *, force_poses: bool) -> None:
        t = self.engine.time
        events = self.engine.take_events()
        due = t >= self._next_pose_sim - 1e-9
        if force_poses or due or events:
            self._publish_poses()
            watched = self.options.mode != "lockstep" or self._watchers
            self._next_pose_sim = t + (self._pose_period if watched else 1.0 / SPARSE_POSE_RATE)
        # Lockstep: at a new world version every status as of this instant (see the module docstring).
        self._publish_states(everything=force_poses and self.options.mode == "lockstep")
        for event in events:
            self._publish_event(event)
        self._publish_human()
        if force_poses or due or events:
            self._publish_clock()

    def _publish_poses(self) -> None:
        for rid, r in self.engine.robots.items():
            if rid in self.engine.external:
                continue  # its driver publishes its pose
            self.publish(
                self.keys.robot_pose(rid), RobotPose(robot=rid, x=r.x, y=r.y, theta=r.theta, vel=r.v, omega=r.omega)
            )

    def _publish_states(self, *, everything: bool) -> None:
        version = self.engine.world_version
        for rid, r in self.engine.robots.items():
            if not (everything or r.status_changed) or rid in self.engine.external:
                continue
            r.status_changed = False
            self.publish(self.keys.robot_status(rid), status_message(r, version))
        doors = self.engine.doors
        changed = set(doors.doors) if everything else self.engine.door_changed
        for did in sorted(changed):
            door = doors[did]
            if did in self.engine.door_changed or did not in self._door_since:
                self._door_since[did] = self.engine.time
            until = door.open_until
            state = DoorState(
                door=did, open=door.passable, by=self.engine.door_by.get(did, ""), until=until, world_version=version
            )
            # Stamped with the time of its last change: a repetition must not look like news.
            state.src, state.seq, state.stamp = self.src, self.next_seq(), self._door_since[did]
            self.publish(self.keys.door_state(did), state, stamp=False)
        self.engine.door_changed = set()

    def _publish_human(self, *, force: bool = False) -> None:
        """HumanState when her place, door, task or the pause changed (``force``: anyway, a heartbeat)."""
        place, door = self.engine.human_place()
        now = (place, door, self.engine.human.done, self.paused)
        if now == self._human_sent and not force:
            return
        self._human_sent = now
        self._last_human_wall = time.monotonic()
        x, y, theta = self.engine.human_pose()
        participant = self.options.human_mode == "participant"
        self.publish(
            self.keys.human_state(),
            HumanState(
                mode=("sensor" if self.options.doors == "sensor" else "participant") if participant else "simulated",
                place=place,
                door=door,
                doors=list(self.engine.human_doors),
                x=x,
                y=y,
                theta=theta,
                task_done=self.engine.human.done,
                paused=self.paused,
                open_time=self.options.human.open_time,
            ),
        )

    def _human_heartbeat(self, wall: float) -> None:
        if wall - self._last_human_wall >= HEARTBEAT:
            self._publish_human(force=True)

    def _publish_event(self, event: SimEvent) -> None:
        msg = Event(data=event.data, robot=event.robot, door=event.door, object=event.object)
        # Stamped with the instant it happened (may fall within the tick), not the tick's end.
        msg.src, msg.seq, msg.stamp = self.src, self.next_seq(), event.time
        self.publish(self.keys.event(), msg, stamp=False)
        if self._events_file is not None:
            self._events_file.write(json.dumps(event.as_dict(), sort_keys=True) + "\n")

    def _blocked(self) -> str:
        return self._waits_for().reason

    def _waits_for(self) -> Wait:
        """In lockstep, what time waits for (the Clock's ``awaiting``) and why, in words
        (:func:`runtime.lockstep.simulator_waits`); ``OPEN`` when it may advance."""
        if self.options.mode != "lockstep":
            return OPEN
        gate = self._gate_waits_for()
        hold = self._camera.hold.blocker() if self._camera is not None and self._camera.hold is not None else ""
        drivers = self._external.blocker() if self._external is not None else ""
        return simulator_waits(gate, hold, drivers)

    def _gate_waits_for(self) -> Wait:
        """What the lockstep gate alone waits for: the human's ack, a plan, or a plan's commands."""
        return self.gate.waits_for(
            self.engine.world_version, {rid: r.last_action_id for rid, r in self.engine.robots.items()}
        )

    def _camera_hold(self) -> None:
        """Lockstep with a camera: take the held frame when one is due; end a hold that timed out."""
        hold = self._camera.hold if self._camera is not None else None
        if hold is None:
            return
        wall = time.monotonic()
        if hold.expired(wall):
            self.count("camera_holds_timed_out")
            if hold.timed_out == 1:
                self.log.warning(
                    "camera frame %s got no overlay on %s within %.1f s: time goes on without it (is an AR client on "
                    "camera %s running?); after %d such frames in a row, frames come at the wall rate until an overlay "
                    "is seen (said once)",
                    hold.seq,
                    self.keys.overlay(self.options.camera.id),
                    hold.timeout,
                    self.options.camera.id,
                    MAX_MISSED,
                )
            return
        t = self.engine.time
        if not hold.due(t):
            self._camera.maybe_render_between_holds(self, wall)  # 0.5 Hz of site time, for recordings
            return
        if hold.suspended:
            hold.skip(t)
            return
        if self._blocked():  # no hold is active, so this is the gate: first the plan answering this instant
            return  # (published after its Intents), so the AR client draws the robots' paths of now, every run
        hold.begin(t, wall)
        self.count("camera_holds")
        # The AR client draws the world as of this instant: its poses and the (paused) clock go first.
        self._publish_poses()
        self._publish_clock()
        hold.framed(self._camera.render(self, wall), time.monotonic())

    def _publish_clock(self) -> None:
        """The clock; ``paused`` when time stands still (lockstep waiting, or the mission over)."""
        self._last_clock_wall = time.monotonic()
        mode = self.options.mode
        rate = self.options.rate if mode == "rate" else 1.0
        awaiting, blocker = self._waits_for() if not self.engine.done else OPEN
        self.publish(
            self.keys.clock(),
            Clock(
                time=self.engine.time,
                mode=mode,
                rate=rate,
                world_version=self.engine.world_version,
                paused=self.engine.done or bool(blocker) or self.paused,
                awaiting=awaiting,
                constraints_version=self.gate.constraints_needed,
            ),
        )

    def _paused_heartbeat(self, wall: float) -> None:
        if wall - self._last_clock_wall >= PAUSED_CLOCK:
            self._publish_clock()
            if self._blocker:
                self.log.debug("t=%.2f still paused: %s", self.engine.time, self._blocker)

    # ------------------------------------------------------------------ feedback

    def _send_feedback(self, request: FeedbackRequest) -> None:
        assert self._sender is not None
        self.gate.feedback_sent()
        self.count("feedback_sent")
        self._sender.send(request, request.kind, dict(request.params))

    def _collect_feedback_answers(self) -> None:
        if self._sender is None:
            return
        for answer in self._sender.answers():
            request = answer.request
            assert isinstance(request, FeedbackRequest)
            if answer.aborted:
                self.log.error(
                    "lockstep aborted at t=%.2f: no ack of the human's feedback %s %s within %.0f wall s "
                    "(is the restrictor running?); going on without it would make this run depend on the "
                    "machine's load, so it ends here, as failed",
                    self.engine.time,
                    request.kind,
                    dict(request.params),
                    self.options.lockstep_abort,
                )
                self.count("feedback_aborted")
                self.exit_code = EXIT_ABORTED
                self.stop()
                return
            ack = answer.ack
            accepted = None if ack is None else ack.accepted
            cv = ack.constraints_version if ack is not None else 0
            self.gate.feedback_answered(accepted, cv)
            self.engine.feedback_answered(
                request, accepted=accepted, reason=ack.reason if ack else "no ack", constraints_version=cv
            )
            self.count(
                "feedback_accepted"
                if accepted
                else ("feedback_refused" if accepted is False else "feedback_unanswered")
            )
            self._publish_tick(force_poses=False)

    # ------------------------------------------------------------------ the end

    def _finish(self) -> None:
        self._finished = True
        wall = time.monotonic() - self._started_wall
        self._publish_states(everything=True)
        self._publish_clock()
        summary = self.engine.summary()
        self.log.info(
            "mission %s at t=%.1f s (team %.1f s), %.1f s wall (%.0fx real time)",
            "done" if self.engine.completed else "ended unfinished",
            self.engine.time,
            summary["team_completion_time"] or float("nan"),
            wall,
            self.engine.time / wall if wall > 0 else float("inf"),
        )
        if self._camera is not None:
            hold = self._camera.hold
            self.log.info(
                "camera %s: %d frames%s",
                self.options.camera.id,
                self._camera.frames,
                f"; {hold.summary()}" if hold else "",
            )
        if self.options.metrics_out:
            out = dict(summary)
            out["run"] = {
                "wall_time": wall,
                "realtime_factor": self.engine.time / wall if wall > 0 else None,
                "counters": self.counters_snapshot(),
            }
            Path(self.options.metrics_out).write_text(
                json.dumps(out, indent=2, sort_keys=True) + "\n", encoding="utf-8"
            )
        if self._events_file is not None:
            self._events_file.flush()
        if self.options.until_done:
            self._exit_at = time.monotonic() + 0.3  # let the last messages leave before closing


def _why(reason: str) -> str:
    return f" ({reason})" if reason else ""
