"""Rules of the execution contract that every executor of RobotCommands applies the same way: the
simulator's robots (services/sim/robots.py) and real robots' drivers (services/robot/).

:func:`command_problem` says why a command cannot be executed from where the robot stands (an
unknown opening, a trajectory that starts too far away, crosses a wall, or does not go through the
opening it names while the robot is not in that doorway already), or returns ``""``;
:func:`dwell_problem` why a ``load``/``unload`` that has arrived cannot start its dwell (the object
out of reach, the robot outside the object's destination room). Who may load what (ownership,
capacity) belongs to whoever tracks the objects.
"""

from __future__ import annotations

import math
from itertools import pairwise

from protocol.actions import STEPS, Action
from protocol.messages import RobotCommand
from protocol.site.model import Site

from .plane import segment_distance, segment_intersection

START_TOLERANCE = 1.5  # m; a trajectory may start at most this far from the robot
REACH = 1.0  # m from the robot's centre within which it can pick up an object


def command_problem(site: Site, x: float, y: float, cmd: RobotCommand, start_tolerance: float = START_TOLERANCE) -> str:
    """Why ``cmd`` cannot be executed by a robot at (x, y), in words; ``""`` if it can."""
    target = cmd.args[0] if cmd.args else ""
    rule = STEPS.get(cmd.action)  # None for a stop
    if rule is not None and rule.arg in ("opening", "door"):
        try:
            opening = site.opening(target)
        except KeyError:
            return f"{cmd.action}: no door or passage {target!r}"
        if rule.arg == "door" and opening.kind != "door":
            return f"opendoor: {target!r} is a passage, not a door"
    if not cmd.trajectory:
        return f"gothrough: empty trajectory cannot go through {target!r}" if cmd.action == Action.GOTHROUGH else ""
    x0, y0 = cmd.trajectory[0][1], cmd.trajectory[0][2]
    gap = math.hypot(x0 - x, y0 - y)
    if gap > start_tolerance:
        return f"trajectory starts {gap:.2f} m from the robot (more than {start_tolerance} m)"
    points = [(x, y)] + [(row[1], row[2]) for row in cmd.trajectory]
    for a, b in pairwise(points):
        for wall in site.walls:
            if segment_intersection(a, b, wall.a, wall.b) is not None:
                return f"trajectory segment {_fmt(a)}->{_fmt(b)} crosses a wall"
    if cmd.action == Action.GOTHROUGH:
        ea, eb = site.opening(target).endpoints
        crosses = any(segment_intersection(a, b, ea, eb) is not None for a, b in pairwise(points))
        # A robot in the doorway (its disc over the opening's line) may be given the rest of its
        # passage: re-commanded off its trajectory, its centre may already be past the line.
        if not crosses and segment_distance((x, y), ea, eb) > site.params.robot_radius:
            return f"gothrough: trajectory does not cross {target!r}"
    return ""


def dwell_problem(
    site: Site, x: float, y: float, cmd: RobotCommand, object_xy: tuple[float, float], reach: float = REACH
) -> str:
    """Why the ``load``/``unload`` ``cmd``, its drive over at (x, y), cannot dwell; ``""`` if it can.
    ``object_xy``: where the object is (for a load)."""
    oid = cmd.args[0]
    if cmd.action == Action.LOAD:
        gap = math.hypot(object_xy[0] - x, object_xy[1] - y)
        return f"load: object {oid!r} is {gap:.2f} m away (reach {reach} m)" if gap > reach else ""
    goes_to = site.objects[oid].deliver_to
    room = site.room_at(x, y)
    if room is None or room.id != goes_to:
        return f"unload: robot is in {room.id if room else 'no room'!r}, object {oid!r} goes to {goes_to!r}"
    return ""


def _fmt(p: tuple[float, float]) -> str:
    return f"({p[0]:.2f}, {p[1]:.2f})"
