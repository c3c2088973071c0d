"""How deep a robot's disc reaches into the site's walls (the executor's wall guard, :mod:`.robots`).

Walls are axis-aligned boxes (``WallSegment.box``: the centre line grown by half the thickness), so
the distance from a disc's centre to each is exact and one numpy expression for all of them.
"""

from __future__ import annotations

import numpy as np

from protocol.site.model import Site


class WallDepth:
    def __init__(self, site: Site, radius: float) -> None:
        boxes = np.array([w.box for w in site.walls], dtype=np.float64).reshape(-1, 4)
        self._x0, self._y0, self._x1, self._y1 = boxes.T
        self.radius = radius

    def depth(self, x: float, y: float) -> float:
        """Metres the disc centred at (x, y) reaches into the nearest wall (<= 0: it touches none)."""
        if self._x0.size == 0:
            return -np.inf
        dx = np.maximum(np.maximum(self._x0 - x, x - self._x1), 0.0)
        dy = np.maximum(np.maximum(self._y0 - y, y - self._y1), 0.0)
        return float(self.radius - np.sqrt(dx * dx + dy * dy).min())
