"""Space-time reservations: the committed trajectories of the robots, as discs moving in time.

A robot that has been sent a trajectory owns, at each instant, the disc of ``robot_radius`` around
the point its trajectory gives for that instant (linear between rows; before the first row it is at
the first point, after the last at the last point: a robot that has arrived stays there until it
is sent something new). Another robot's trajectory is *clear* of the table when its disc stays at
least ``2 * radius + margin`` from every such disc at every instant, checked every ``dt`` seconds
(``dt`` times ``robot_speed`` is well under the margin, so nothing passes between two checks).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

Rows = Sequence[Sequence[float]]  # [t, x, y, theta]

MARGIN = 0.05  # m kept between two robots' discs
DT = 0.2  # s between checks


@dataclass
class ReservationTable:
    radius: float
    margin: float = MARGIN
    _rows: dict[str, np.ndarray] = field(default_factory=dict)  # robot -> (n, 3) array of t, x, y

    @property
    def clearance(self) -> float:
        """Least distance between two robots' centres."""
        return 2.0 * self.radius + self.margin

    def reserve(self, robot: str, rows: Rows) -> None:
        if rows:
            self._rows[robot] = np.asarray([[r[0], r[1], r[2]] for r in rows], dtype=float)

    def release(self, robot: str) -> None:
        self._rows.pop(robot, None)

    def paths(self) -> dict[str, np.ndarray]:
        """Each reserved robot's rows (t, x, y)."""
        return dict(self._rows)

    def horizon(self) -> float:
        """After this time every reserved robot stands still (at the end of its trajectory)."""
        return max((float(r[-1, 0]) for r in self._rows.values()), default=-np.inf)

    def positions(
        self, times: np.ndarray, exclude: str = "", near: tuple[float, float, float, float] | None = None
    ) -> np.ndarray:
        """Centres of every reserved robot but ``exclude`` at ``times``: shape (len(times), robots, 2).
        ``near`` (x0, y0, x1, y1): only robots whose whole trajectory comes within a clearance of it."""
        out = [
            np.stack([np.interp(times, rows[:, 0], rows[:, 1]), np.interp(times, rows[:, 0], rows[:, 2])], axis=-1)
            for rid, rows in sorted(self._rows.items())
            if rid != exclude and (near is None or self._comes_near(rows, near))
        ]
        if not out:
            return np.zeros((len(times), 0, 2))
        return np.stack(out, axis=1)

    def _comes_near(self, rows: np.ndarray, box: tuple[float, float, float, float]) -> bool:
        c = self.clearance
        return bool(
            rows[:, 1].min() <= box[2] + c
            and rows[:, 1].max() >= box[0] - c
            and rows[:, 2].min() <= box[3] + c
            and rows[:, 2].max() >= box[1] - c
        )

    def first_conflict(self, robot: str, rows: Rows, until: float | None = None) -> tuple[float, str] | None:
        """The first instant (and robot) at which ``robot`` following ``rows`` (then standing at their
        end until ``until``, default the table's horizon) comes closer than :attr:`clearance`."""
        if not rows:
            return None
        mine = np.asarray([[r[0], r[1], r[2]] for r in rows], dtype=float)
        end = max(float(mine[-1, 0]), self.horizon() if until is None else until)
        times = np.arange(float(mine[0, 0]), end + DT, DT)
        others = [rid for rid in sorted(self._rows) if rid != robot]
        if not others:
            return None
        here = np.stack([np.interp(times, mine[:, 0], mine[:, 1]), np.interp(times, mine[:, 0], mine[:, 2])], axis=-1)
        there = self.positions(times, exclude=robot)
        d = np.linalg.norm(there - here[:, None, :], axis=-1)
        hit = np.argwhere(d < self.clearance - 1e-9)
        if hit.size == 0:
            return None
        k, j = hit[0]
        return float(times[k]), others[j]
