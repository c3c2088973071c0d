"""What `arroch planner` is run with, beside the site: the planning method and the task planner's
settings, how far off its trajectory a robot may be, and whether trajectories are timed against
each other."""

from __future__ import annotations

from dataclasses import dataclass, field

from .planner import PlannerSettings

OFF_TRACK = 1.0  # m from the commanded trajectory that counts as "far off"


@dataclass
class ServiceSettings:
    method: str = "iidp"
    planner: PlannerSettings = field(default_factory=lambda: PlannerSettings(time_limit=5.0))
    off_track: float = OFF_TRACK
    collision_free: bool = False  # time trajectories against each other (teammotion.py; opt-in, see the docs)
