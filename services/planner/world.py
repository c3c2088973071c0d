"""The world as the planner sees it: where each robot is, what it carries and does, which doors are open.

The service keeps one :class:`World` up to date from poses, statuses and door states; the one-shot
CLI and the benchmarks start from :func:`initial_world` (the site file's start). Planning reads a
snapshot and never changes it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from protocol.site import Site


@dataclass(frozen=True)
class InProgress:
    """An action the robot is in the middle of and must finish before anything else.

    Only actions that cannot be dropped halfway are kept: a ``gothrough`` while in the doorway
    (``target`` is the room it is entering) and a ``load``/``unload`` while working in place.
    ``until`` is the site-clock time it is expected to end."""

    action: str
    args: tuple[str, ...]
    until: float
    target: str = ""


@dataclass(frozen=True)
class RobotState:
    id: str
    pose: tuple[float, float, float]  # x, y, theta
    carrying: frozenset[str] = frozenset()
    delivered: frozenset[str] = frozenset()
    beside: str = ""  # opening the robot stands beside (waiting for a door, or just approached)
    in_progress: InProgress | None = None


@dataclass(frozen=True)
class World:
    now: float  # site-clock seconds
    robots: dict[str, RobotState]
    # human-operated doors open right now -> site-clock time the human opened them
    open_doors: dict[str, float] = field(default_factory=dict)

    @property
    def delivered(self) -> frozenset[str]:
        out: set[str] = set()
        for robot in self.robots.values():
            out |= robot.delivered
        return frozenset(out)

    def with_now(self, now: float) -> World:
        return replace(self, now=now)


def initial_world(site: Site, now: float = 0.0) -> World:
    """Every robot at its start pose, nothing carried or delivered, every door closed."""
    robots = {rid: RobotState(id=rid, pose=spec.start) for rid, spec in site.robots.items()}
    return World(now=now, robots=robots)
