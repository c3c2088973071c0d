"""How far paths planned on an occupancy grid keep a robot's disc off the walls.

A path is planned for the robot's centre on a grid whose obstacles are inflated by the robot's
radius plus :func:`wall_clearance`: the task planner's motion planner (services/planner/motion.py)
and the simulator's ways around other robots (services/sim/avoidance.py) use the same grid, so both
keep the same clearance. Two errors eat into it, and the clearance is their sum, so that the disc
of a robot following such a path never reaches a wall:

- the controller's tracking error: how far pure pursuit takes the robot's centre from the path it
  follows (:data:`runtime.pursuit.TRACKING_ERROR`, measured);
- the grid's discretisation: a path is checked cell by cell, and a point of a free cell lies up to
  half a cell's diagonal from the cell's centre; the inflation measures from the obstacle cell's
  centre less half a cell (``protocol.site.grid.inflate_occupied``), which overstates the distance
  to that cell's corner by up to (sqrt(2) - 1) / 2 of a cell. Together: (sqrt(2) - 1/2) of a cell.

With the site's 0.25 m robots on the planner's 0.05 m grid that is 0.02 + 0.046 m: an inflation of
0.316 m, which leaves at least three free cells across an 0.8 m door (the narrowest the sites have).
"""

from __future__ import annotations

import math

from .pursuit import TRACKING_ERROR


def discretisation(resolution: float) -> float:
    """m by which a point on a path checked against a grid of ``resolution`` m cells may lie nearer
    an obstacle than the grid's inflation says."""
    return resolution * (math.sqrt(2.0) - 0.5)


def wall_clearance(resolution: float) -> float:
    """m to inflate obstacles by beyond the robot's radius on a grid of ``resolution`` m cells, so
    that a robot following a path planned on it never touches a wall."""
    return TRACKING_ERROR + discretisation(resolution)
