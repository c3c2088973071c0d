"""Keeping the pybullet scene in step with the engine, lazily.

The engine steps kinematically; the pybullet :class:`~services.sim.world.World` is only needed
when something looks at the scene (a camera frame). :meth:`WorldMirror.sync` pushes what changed
since the previous sync (robot poses, door leaves, objects picked up or put down, the human), so
a sync before each frame costs a handful of pybullet calls, and nothing at all between frames.
"""

from __future__ import annotations

from typing import Any

from .engine import Engine
from .objects import FLOOR_HEIGHT  # the World puts an object's centre this high on the floor


class WorldMirror:
    def __init__(self, world: Any, engine: Engine) -> None:
        self.world = world
        self.engine = engine
        self._robots: dict[str, tuple[float, float, float]] = {}
        self._doors: dict[str, float] = {}
        self._carriers: dict[str, str | None] = {}
        self._human: tuple[float, float, float] | None = None
        self.calls = 0  # pybullet-facing calls made, for benchmarks and tests

    def sync(self) -> int:
        """Push every change since the last sync; returns the number of World calls it took."""
        before = self.calls
        for rid, robot in self.engine.robots.items():
            pose = (robot.x, robot.y, robot.theta)
            if self._robots.get(rid) != pose:
                self.world.set_robot_pose(rid, *pose)
                self._robots[rid] = pose
                self.calls += 1
        for did, door in self.engine.doors.doors.items():
            if self._doors.get(did) != door.fraction:
                self.world.set_door_opening(did, door.fraction)
                self._doors[did] = door.fraction
                self.calls += 1
        objects = self.engine.objects
        for oid in sorted(objects.changed):
            obj = objects[oid]
            if oid in self._carriers and self._carriers[oid] == obj.carrier and obj.carrier is not None:
                continue
            if obj.carrier is not None:
                self.world.attach_object(oid, obj.carrier)  # rides on the robot from now on
            else:
                self.world.attach_object(oid, None)
                self.world.set_object_pose(oid, obj.x, obj.y, FLOOR_HEIGHT)
                self.calls += 1
            self._carriers[oid] = obj.carrier
            self.calls += 1
        objects.changed.clear()
        human = self.engine.human_pose()
        if human != self._human:
            self.world.set_human_pose(*human)
            self._human = human
            self.calls += 1
        return self.calls - before
