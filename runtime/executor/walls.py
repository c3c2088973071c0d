"""How deep a robot's disc reaches into the site's walls: the executor's wall guard (:mod:`.executor`),
and the simulator's count of robot-wall contacts (``services/sim/walls.py``).

Walls are axis-aligned boxes (``WallSegment.box``: the centre line grown by half the thickness), so
the distance from a disc's centre to each is exact and one numpy expression for all of them.
"""

from __future__ import annotations

import numpy as np

from protocol.site.model import Site

#: m a disc may reach into a wall and still only touch it: float rounding at the limit. The executor's
#: wall guard allows no deeper step (``RobotConfig.wall_tolerance``), and the simulator counts a
#: deeper disc as a contact (``services/sim/walls.py``).
TOUCH = 1e-3
KNOWN_POINTS = 4096  # depths remembered (a few ticks of every robot's poses and candidate steps)


class WallDepth:
    def __init__(self, site: Site, radius: float) -> None:
        boxes = np.array([w.box for w in site.walls], dtype=np.float64).reshape(-1, 4)
        self._x0, self._y0, self._x1, self._y1 = boxes.T
        self.radius = radius
        # Depths of points asked lately: a robot's pose is asked again and again (by the watch every
        # tick, by the guard as "before" after it was the step's "after"), and the depth of a point
        # never changes. Cleared when full, so it stays small.
        self._known: dict[tuple[float, float], float] = {}

    def away(self, x: float, y: float) -> tuple[float, float] | None:
        """The unit vector from the nearest wall's nearest point to (x, y): the way out of that wall
        (None without walls, or for a centre inside one)."""
        if self._x0.size == 0:
            return None
        nearest_x = np.clip(x, self._x0, self._x1)
        nearest_y = np.clip(y, self._y0, self._y1)
        dx, dy = x - nearest_x, y - nearest_y
        k = int(np.argmin(dx * dx + dy * dy))
        length = float(np.hypot(dx[k], dy[k]))
        return None if length == 0.0 else (float(dx[k]) / length, float(dy[k]) / length)

    def depth(self, x: float, y: float) -> float:
        """Metres the disc centred at (x, y) reaches into the nearest wall (<= 0: it touches none)."""
        known = self._known.get((x, y))
        if known is not None:
            return known
        if self._x0.size == 0:
            return -np.inf
        dx = np.maximum(np.maximum(self._x0 - x, x - self._x1), 0.0)
        dy = np.maximum(np.maximum(self._y0 - y, y - self._y1), 0.0)
        depth = float(self.radius - np.sqrt(dx * dx + dy * dy).min())
        if len(self._known) >= KNOWN_POINTS:
            self._known.clear()
        self._known[(x, y)] = depth
        return depth
