"""A safety invariant checked every tick: no two robots' discs intersect.

Robots are discs of the site's ``robot_radius``; two discs whose centres are closer than twice
that overlap, which in a building is a collision. Like :mod:`services.sim.crossings`, this watch
checks the outcome independently of how the planner and the executor avoid it, and counts edges:
a pair that starts to overlap is one overlap however many ticks it lasts, and counts again only
after the discs have come apart.

Each overlap is filed under the pair and the *place* it happened: the opening (door or passage)
whose gap lies under the point between the two centres, else the room holding that point.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from protocol.site.model import Site
from runtime.executor import Robot
from runtime.plane import segment_distance

# Overlap below this (m) is touching, not colliding (float rounding of two robots at the limit).
TOLERANCE = 1e-3


def place(site: Site, radius: float, x: float, y: float) -> str:
    """The opening whose gap is within ``radius`` of (x, y), else the room there, else "outside"."""
    for opening in site.openings.values():
        a, b = opening.endpoints
        if segment_distance((x, y), a, b) < radius:
            return opening.id
    room = site.room_at(x, y)
    return room.id if room is not None else "outside"


@dataclass(frozen=True)
class Overlap:
    robots: tuple[str, str]  # sorted pair
    place: str  # opening id, room id, or "outside"
    depth: float  # m the discs interpenetrate (2 * radius - centre distance)
    poses: tuple[tuple[float, float], tuple[float, float]]


class OverlapWatch:
    """Reports each pair of robots whose discs start to intersect (edge-triggered)."""

    def __init__(self, site: Site, radius: float) -> None:
        self.site = site
        self.radius = radius
        self._touching: set[tuple[str, str]] = set()

    def check(self, robots: Iterable[Robot]) -> list[Overlap]:
        """The pairs that started to overlap since the last check (call once per tick)."""
        robots = sorted(robots, key=lambda r: r.id)
        limit = 2.0 * self.radius - TOLERANCE
        touching: set[tuple[str, str]] = set()
        started: list[Overlap] = []
        for i, a in enumerate(robots):
            for b in robots[i + 1 :]:
                d = math.hypot(a.x - b.x, a.y - b.y)
                if d >= limit:
                    continue
                pair = (a.id, b.id)
                touching.add(pair)
                if pair not in self._touching:
                    mx, my = (a.x + b.x) / 2.0, (a.y + b.y) / 2.0
                    started.append(
                        Overlap(
                            pair,
                            place(self.site, self.radius, mx, my),
                            round(2.0 * self.radius - d, 6),
                            ((round(a.x, 6), round(a.y, 6)), (round(b.x, 6), round(b.y, 6))),
                        )
                    )
        self._touching = touching
        return started
