"""From a team plan to what each robot is told: its front action as a RobotCommand with a trajectory.

Algorithm 1, lines 4-11: for each robot with a non-empty plan, take the front action, get the
robot's configuration, and let the motion planner make the trajectory for that action.

Action ids increase per robot and are never reused (the counter also starts past any id a robot
reports, so a restarted planner does not repeat one). A front action that is the same as the one
the robot is already executing keeps its id and is not sent again, so a replan caused by another
robot does not restart a robot's load or make it stop and go; it is sent anew when the robot has
left its trajectory (``force``), or when the robot reports that action over.

With ``team`` (collision-free motion, opt-in: ``arroch planner --collision-free``), every new trajectory is timed
against the trajectories already sent (:mod:`services.planner.teammotion`), and
:meth:`Dispatcher.with_waits` moves each robot's plan by the waits that added.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from protocol.actions import Action
from protocol.messages import Intent, RobotCommand

from .motion import MotionPlanner, Point
from .plan import RobotPlan, Step, TeamResult
from .problem import ProblemBuilder
from .teammotion import TeamMotion, delay_plan
from .world import World

FINISHED_STATES = ("done", "failed", "idle")


@dataclass
class Dispatched:
    action: str
    args: tuple[str, ...]
    action_id: int
    plan_id: int
    trajectory: list[list[float]]
    duration: float = 0.0
    command: RobotCommand | None = None  # as sent, to send again if the robot never got it


@dataclass
class Dispatcher:
    builder: ProblemBuilder
    motion: MotionPlanner
    current: dict[str, Dispatched] = field(default_factory=dict)
    # index of each robot's front step in its plan (1 when a leading opendoor is skipped)
    front_index: dict[str, int] = field(default_factory=dict)
    _next_id: dict[str, int] = field(default_factory=dict)
    team: TeamMotion | None = None  # collision-free motion (None: each trajectory on its own)

    def note_reported_id(self, robot: str, action_id: int) -> None:
        """Keep new ids above anything the robot has seen (e.g. from before a planner restart)."""
        if action_id >= self._next_id.get(robot, 1):
            self._next_id[robot] = action_id + 1

    def _new_id(self, robot: str) -> int:
        n = self._next_id.get(robot, 1)
        self._next_id[robot] = n + 1
        return n

    def dispatch(
        self,
        result: TeamResult,
        world: World,
        plan_id: int,
        *,
        finished: set[str] = frozenset(),  # type: ignore[assignment]
        force: set[str] = frozenset(),  # type: ignore[assignment]
    ) -> tuple[list[RobotCommand], dict[str, int]]:
        """Commands to send for ``result`` and the action id of each robot's front step.

        ``finished``: robots that reported their current action over; ``force``: robots whose
        command must be sent again (e.g. far off their trajectory)."""
        commands: list[RobotCommand] = []
        front_ids: dict[str, int] = {}
        if self.team is not None:
            kept = {rid: d.trajectory for rid, d in self.current.items() if rid not in finished | force}
            self.team.begin(world, kept)
        for rid, plan in sorted(result.plans.items()):
            if plan.empty:
                self.forget(rid)
                continue
            state = world.robots.get(rid)
            if state is None:
                continue
            index = self.front(plan, world)
            self.front_index[rid] = index
            step = plan.steps[index]
            now_cmd = self.current.get(rid)
            same = now_cmd is not None and now_cmd.action == step.action and now_cmd.args == step.args
            if same and rid not in finished and rid not in force:
                front_ids[rid] = now_cmd.action_id
                continue
            trajectory, duration = self.trajectory(rid, plan, step, world)
            if self.team is not None and trajectory:
                trajectory = self.team.timed(
                    rid,
                    trajectory,
                    world.now,
                    not_before=result.base + step.start if step.action == "gothrough" else None,
                    planned_end=result.base + step.end - duration,
                    movable_goal=step.action in ("approach", "gothrough"),
                )
            action_id = self._new_id(rid)
            cmd = RobotCommand(
                robot=rid,
                plan_id=plan_id,
                action_id=action_id,
                action=step.action,
                args=list(step.args),
                trajectory=trajectory,
                duration=duration,
            )
            self.current[rid] = Dispatched(step.action, step.args, action_id, plan_id, trajectory, duration, cmd)
            front_ids[rid] = action_id
            commands.append(cmd)
        return commands, front_ids

    def with_waits(self, result: TeamResult) -> TeamResult:
        """``result`` with each robot's plan moved by the wait its new trajectory added (if any)."""
        if self.team is None or not self.team.delays:
            return result
        plans = dict(result.plans)
        for rid, seconds in self.team.delays.items():
            if rid in plans:
                plans[rid] = delay_plan(plans[rid], self.front_index.get(rid, 0), seconds)
        return replace(result, plans=plans)

    @staticmethod
    def front(plan: RobotPlan, world: World) -> int:
        """Index of the step to dispatch: 0, or 1 when the plan starts with ``opendoor(D)`` for a
        door that is open now, followed by ``gothrough(D)``.

        An opendoor on an open door is done at once (execution contract), and each action done is a
        new world version that is answered by a new plan starting with that same opendoor again:
        robots would open an open door forever, at nearly constant sim time, until it closes. The
        door being open is what the opendoor waits for, so the gothrough comes next. (If the plan
        meant to pass in a later opening, a robot that reaches the door after it closed waits at it.)
        """
        steps = plan.steps
        if (
            len(steps) >= 2
            and steps[0].action == Action.OPENDOOR
            and steps[1].action == Action.GOTHROUGH
            and steps[0].args[:1] == steps[1].args[:1]
            and steps[0].args[:1]
            and steps[0].args[0] in world.open_doors
        ):
            return 1
        return 0

    def resend(self, robot: str) -> RobotCommand | None:
        """The command last sent to ``robot`` (same id), to publish again when it never arrived."""
        sent = self.current.get(robot)
        return sent.command if sent is not None else None

    def sent_commands(self) -> list[RobotCommand]:
        """Each robot's current command, as sent. Called on Zenoh's thread: the dict is copied in one step."""
        sent = list(self.current.values())
        return [d.command for d in sent if d.command is not None]

    def intents(self, plan_id: int) -> list[Intent]:
        """What every robot with a command is about to follow (for the AR client)."""
        return [
            Intent(
                robot=rid,
                plan_id=plan_id,
                action_id=d.action_id,
                action=d.action,
                args=list(d.args),
                trajectory=d.trajectory,
            )
            for rid, d in sorted(self.current.items())
        ]

    def forget(self, robot: str) -> None:
        self.current.pop(robot, None)
        self.front_index.pop(robot, None)

    # ------------------------------------------------------------------ trajectories

    def _queue_spot(self, rid: str, opening: str, room: str, world: World) -> Point:
        """The first of the opening's queue spots on ``room``'s side that no other robot is sent to
        (approaching it) or stands at (ProblemBuilder.queue_spots); the last one when all are taken."""
        taken = [(state.pose[0], state.pose[1]) for other, state in world.robots.items() if other != rid]
        for other, sent in self.current.items():
            if other != rid and sent.action == Action.APPROACH and sent.args[:1] == (opening,) and sent.trajectory:
                taken.append((sent.trajectory[-1][1], sent.trajectory[-1][2]))
        spots = self.builder.queue_spots(opening, room)
        return next((s for s in spots if all(math.dist(s, t) > 0.3 for t in taken)), spots[-1])

    def trajectory(self, rid: str, plan: RobotPlan, step: Step, world: World) -> tuple[list[list[float]], float]:
        """The front action's trajectory from the robot's pose, starting now, and its time in place."""
        state = world.robots[rid]
        pose: Point = (state.pose[0], state.pose[1])
        theta = state.pose[2]
        now = world.now
        room = self.builder.robot_room(state)
        arg = step.args[0] if step.args else ""
        motion = self.motion
        if step.action == "approach":
            path = motion.path(pose, self._queue_spot(rid, arg, room, world), (room,))
            return motion.trajectory(path.points, now, theta0=theta), 0.0
        if step.action == "opendoor":
            cx, cy = self.builder.site.opening(arg).center
            return [[now, pose[0], pose[1], math.atan2(cy - pose[1], cx - pose[0])]], 0.0
        if step.action == "gothrough":
            opening = self.builder.site.opening(arg)
            ip = state.in_progress
            target = ip.target if ip is not None and ip.action == "gothrough" and ip.args[:1] == (arg,) else ""
            target = target or next((p.dst for p in plan.passes if p.opening == arg and p.dst), "")
            if target not in opening.rooms:
                target = opening.other(room) if room in opening.rooms else opening.rooms[1]
            near = self.builder.wait_point(arg, opening.other(target))
            far = self.builder.beside(arg, target)
            points: list[Point] = [pose]
            # Line up in front of the opening unless already in it or beside it.
            if math.dist(pose, near) > 0.05 and math.dist(pose, far) > math.dist(near, far):
                points += list(motion.path(pose, near, (opening.other(target),)).points[1:])
            points += list(motion.path(points[-1], far, opening.rooms).points[1:])
            return motion.trajectory(points, now, theta0=theta), 0.0
        if step.action in ("load", "unload"):
            spec = self.builder.site.objects[arg]
            target = self.builder.object_point(arg) if step.action == "load" else self.builder.drop_point(arg)
            target_room = spec.room if step.action == "load" else spec.deliver_to
            path = motion.path(pose, target, (target_room, room))
            return motion.trajectory(path.points, now, theta0=theta), float(self.builder.params.load_time)
        return [], 0.0
