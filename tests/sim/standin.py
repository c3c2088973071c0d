"""A stand-in for the planner (and the restrictor's ack), to drive the simulator in tests and
benchmarks without clingo: each robot fetches its objects one after the other, room to room along
the shortest chain of openings, with straight-line trajectories (rooms are convex rectangles).

:class:`ScriptedPlanner` is the pure part (what to command next); :class:`StandInPlanner` puts it
on Zenoh the way docs/services/robot.md's execution contract asks: a TeamPlan answering every world
version (and every constraints version it acknowledged), a RobotCommand for each robot's front
action. It answers world version ``w`` only once it has heard every event announcing versions up
to ``w``, so its decisions do not depend on message timing and lockstep runs repeat exactly.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from dataclasses import dataclass

import msgspec

from protocol.messages import Clock, ConstraintSet, Event, Feedback, FeedbackAck, PlanStep, RobotCommand, TeamPlan
from protocol.site.model import Site
from runtime.service import Service
from runtime.transport import ZenohOptions

STANDOFF = 0.6  # m in front of an opening where approach ends and gothrough arrives


@dataclass
class Task:
    action: str
    args: list[str]
    target: tuple[float, float] | None  # where the trajectory ends (None: no trajectory)
    via: tuple[float, float] | None = None  # a point the trajectory passes first (in front of the opening)


def route(site: Site, start: str, goal: str) -> list[tuple[str, str, str]]:
    """Shortest chain of (opening, from_room, to_room) from room ``start`` to room ``goal`` (BFS)."""
    prev: dict[str, tuple[str, str] | None] = {start: None}
    queue = deque([start])
    while queue:
        room = queue.popleft()
        if room == goal:
            break
        for opening, other in site.neighbours(room):
            if other not in prev:
                prev[other] = (opening, room)
                queue.append(other)
    hops: list[tuple[str, str, str]] = []
    room = goal
    while prev[room] is not None:
        opening, before = prev[room]  # type: ignore[misc]
        hops.append((opening, before, room))
        room = before
    return hops[::-1]


def tasks_for(site: Site, robot: str) -> list[Task]:
    """The whole action list of one robot: for each of its objects, go load it, bring it home."""
    out: list[Task] = []
    room = site.robots[robot].room
    drop = 0
    for obj in sorted((o for o in site.objects.values() if o.robot == robot), key=lambda o: o.id):
        for goal, final in ((obj.room, Task("load", [obj.id], obj.position)), (obj.deliver_to, None)):
            for opening, a, b in route(site, room, goal):
                o = site.opening(opening)
                out.append(Task("approach", [o.id], o.beside(a, STANDOFF)))
                if o.kind == "door" and o.human_operated:
                    out.append(Task("opendoor", [o.id], None))
                # via the point in front of it: a robot that queued behind another is elsewhere
                out.append(Task("gothrough", [o.id], o.beside(b, STANDOFF), o.beside(a, STANDOFF)))
            room = goal
            if final is None:
                cx, cy = site.rooms[goal].center
                final = Task("unload", [obj.id], (cx + 0.3 * (drop % 3 - 1), cy + 0.3 * (drop // 3 % 3 - 1)))
                drop += 1
            out.append(final)
    return out


def trajectory(
    start: tuple[float, float, float],
    target: tuple[float, float],
    now: float,
    speed: float,
    via: tuple[float, float] | None = None,
) -> list[list[float]]:
    """Straight lines from the robot (through ``via`` when it is more than 5 cm away) to ``target``,
    timed at ``speed``; rows [t, x, y, theta]."""
    x, y, theta = start
    points = [p for p in (via, target) if p is not None]
    if via is not None and math.dist((x, y), via) <= 0.05:
        points = [target]
    rows = []
    t = now
    for p in points:
        heading = math.atan2(p[1] - y, p[0] - x) if math.dist((x, y), p) > 1e-6 else theta
        if not rows:
            rows.append([t, x, y, heading])
        t += math.dist((x, y), p) / speed
        rows.append([t, p[0], p[1], heading])
        x, y, theta = p[0], p[1], heading
    return rows


class ScriptedPlanner:
    """Which command each robot gets next; pure (no I/O)."""

    def __init__(self, site: Site) -> None:
        self.site = site
        self.todo = {rid: tasks_for(site, rid) for rid in sorted(site.robots)}
        self.busy: dict[str, int] = {}  # robot -> action_id of its command in progress
        self.next_id = {rid: 0 for rid in site.robots}
        self.fronts: dict[str, int] = {}
        self.failures: dict[str, int] = {rid: 0 for rid in site.robots}

    def finished(self, robot: str, action_id: int, ok: bool) -> None:
        if self.busy.get(robot) != action_id:
            return
        del self.busy[robot]
        if ok:
            self.todo[robot].pop(0)
            self.failures[robot] = 0
        else:
            self.failures[robot] += 1
            if self.failures[robot] > 2:
                self.todo[robot] = []  # give up on this robot rather than loop

    def commands(self, plan_id: int, now: float, poses: dict[str, tuple[float, float, float]]) -> list[RobotCommand]:
        out = []
        for rid in sorted(self.todo):
            if rid in self.busy or not self.todo[rid]:
                continue
            task = self.todo[rid][0]
            self.next_id[rid] += 1
            speed = self.site.params.robot_speed
            rows = trajectory(poses[rid], task.target, now, speed, task.via) if task.target else []
            duration = self.site.params.load_time if task.action in ("load", "unload") else 0.0
            out.append(
                RobotCommand(
                    robot=rid,
                    plan_id=plan_id,
                    action_id=self.next_id[rid],
                    action=task.action,
                    args=task.args,
                    trajectory=rows,
                    duration=duration,
                )
            )
            self.busy[rid] = self.next_id[rid]
        return out

    def plan_steps(self, now: float) -> dict[str, list[PlanStep]]:
        steps = {}
        for rid, todo in self.todo.items():
            steps[rid] = [
                PlanStep(
                    action=t.action, args=t.args, start=now, end=now, action_id=self.busy.get(rid, 0) if i == 0 else 0
                )
                for i, t in enumerate(todo)
            ]
        return steps


class StandInPlanner(Service):
    """The scripted planner on Zenoh, plus a restrictor stand-in answering feedback queries."""

    def __init__(
        self, site: Site, namespace: str, endpoint: str, *, accept_feedback: bool = True, restrictor: bool = True
    ) -> None:
        super().__init__("standin", namespace, ZenohOptions(mode="client", connect=[endpoint]))
        self.site = site
        self.script = ScriptedPlanner(site)
        self.accept_feedback = accept_feedback
        self.restrictor = restrictor  # False: a real restrictor answers; follow its ConstraintSet
        self.lock = threading.Lock()
        self.poses: dict[str, tuple[float, float, float]] = {rid: r.start for rid, r in site.robots.items()}
        self.versions_seen: set[int] = set()
        self.answered = 0
        self.constraints_version = 0
        self.plans = 0
        self.feedback: list[Feedback] = []

    def setup(self) -> None:
        # No pose subscription: each event carries the pose of its robot, and only robots that just
        # finished (or failed) an action get a new command.
        self.subscribe(self.keys.event(), Event, self._on_event)
        # A late start (the sim already waiting for its first plan) is learnt from the clock.
        self.subscribe(self.keys.clock(), Clock, self._on_clock)
        if self.restrictor:
            self.serve(self.keys.feedback(), self._on_feedback)
        else:
            self.subscribe(self.keys.constraints(), ConstraintSet, self._on_constraints)

    def _on_clock(self, clock: Clock, key: str) -> None:
        with self.lock:
            if self.answered == 0 and clock.world_version == 1 and clock.time == 0.0:
                self.versions_seen.add(1)
                self.answered = 1
                self._publish_plan(0.0)

    def _on_constraints(self, cs: ConstraintSet, key: str) -> None:
        with self.lock:
            if cs.version > self.constraints_version:
                self.constraints_version = cs.version
                if self.answered:
                    self._publish_plan(cs.stamp)  # replan on new constraints, as the planner does

    def _on_event(self, event: Event, key: str) -> None:
        # the kind's fields as a map (a Struct per kind; counters of `stats` are a map already)
        data = event.data if isinstance(event.data, dict) else msgspec.to_builtins(event.data)
        with self.lock:
            pose = data.get("pose")
            if event.robot in self.poses and isinstance(pose, list) and len(pose) == 3:
                # The pose the event carries, not the pose stream: subscriptions on different keys
                # are not ordered with each other, the event's own data is.
                self.poses[event.robot] = (float(pose[0]), float(pose[1]), float(pose[2]))
            if event.kind in ("action_done", "action_failed") and event.robot in self.script.todo:
                self.script.finished(event.robot, int(data.get("action_id", -1)), event.kind == "action_done")
            version = data.get("world_version")
            if isinstance(version, int):
                self.versions_seen.add(version)
            # Answer the highest version up to which nothing is missing.
            target = self.answered
            while target + 1 in self.versions_seen:
                target += 1
            if target > self.answered:
                self.answered = target
                self._publish_plan(event.stamp)

    def _publish_plan(self, now: float) -> None:
        self.plans += 1
        for cmd in self.script.commands(self.plans, now, self.poses):
            self.publish(self.keys.robot_command(cmd.robot), cmd)
        plan = TeamPlan(
            plan_id=self.plans,
            world_version=self.answered,
            constraints_version=self.constraints_version,
            method="standin",
            robots=self.script.plan_steps(now),
        )
        self.publish(self.keys.plan(), plan)

    def _on_feedback(self, query) -> FeedbackAck | None:  # noqa: ANN001
        from protocol.codec import decode

        payload = query.payload.to_bytes() if query.payload is not None else b""
        msg = decode(payload, Feedback)
        with self.lock:
            self.feedback.append(msg)
            if self.accept_feedback:
                self.constraints_version += 1
            ack = self.stamp(
                FeedbackAck(
                    to=msg.src,
                    feedback_seq=msg.seq,
                    accepted=self.accept_feedback,
                    constraints_version=self.constraints_version,
                    reason="" if self.accept_feedback else "refused by the stand-in",
                )
            )
            if self.accept_feedback and self.answered:
                self._publish_plan(msg.stamp)
        return ack


class LossyStandIn(StandInPlanner):
    """The stand-in whose publications of some plans (and of those plans' commands) are lost on the
    way, as they were once between a real planner and the simulator; like the planner, it answers
    queries for its last plan and for each robot's last command."""

    def __init__(self, *args: object, lose: frozenset[int] = frozenset({2, 4}), **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.lose = lose  # plan numbers whose publications never arrive
        self.lost = 0
        self.last_plan: TeamPlan | None = None
        self.last_commands: dict[str, RobotCommand] = {}  # command key -> the command last sent on it

    def setup(self) -> None:
        super().setup()
        self.serve(self.keys.plan(), lambda _query: self.last_plan)
        self.serve_each(self.keys.robot_command(), lambda _query: list(self.last_commands.items()))

    def publish(self, key: str, msg, *, stamp: bool = True, extra=None) -> None:  # noqa: ANN001
        if stamp:
            self.stamp(msg)  # as it went out: a query is answered with the very message
        if isinstance(msg, TeamPlan):
            self.last_plan = msg
        elif isinstance(msg, RobotCommand):
            self.last_commands[key] = msg
        if self.plans in self.lose:
            self.lost += 1
            return
        super().publish(key, msg, stamp=False, extra=extra)
