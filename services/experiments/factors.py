"""The factors a point of a sweep may set, where each one goes, and its legal range.

A *point* (``SweepSpec.points``) is a mapping from factor names to values: one building and one
human model for a whole group of trials (a capacity and door share of the detour sweep, one
sample of the sensitivity analysis, one simulated person of a population). Each factor goes to
exactly one place:

- ``key``: a trial-key field the sim gets on its command line and trials.csv has a column for
  (the door-opening probability, her mean task length, the interruption cost);
- ``site``: an option of the site generator (``robot_capacity``, ``door_hold_time``; ``door_share``
  of :func:`runtime.site.generate_detour.generate_detour_site`);
- ``human``: a field of the sim's human model (``services/sim/human.py``, ``HumanConfig``), written
  to the trial's ``--human-config`` file.

``limits`` are what the simulator accepts (its own checks stay the authority: a value outside
them fails the trial by name); a population's draws are kept inside them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

INF = math.inf


@dataclass(frozen=True)
class Factor:
    name: str  # the point's key and trials.csv's column
    target: str  # key, site or human (module docstring)
    option: str  # the trial-key field, generator option or HumanConfig field it sets
    limits: tuple[float, float]  # legal values (inclusive)
    integer: bool = False
    unit: str = ""

    def clip(self, value: float) -> float:
        """``value`` inside the limits, rounded for an integer factor, and to six significant digits: the
        text trials.csv holds (``format_p``), so a point's value reads back from the CSV as itself."""
        low, high = self.limits
        value = min(max(value, low), high)
        return float(round(value)) if self.integer else float(f"{value:.6g}")


_FACTORS = (
    Factor("door_probability", "key", "p", (0.0, 1.0)),
    Factor("task_mean", "key", "task", (1.0, INF), unit="s"),
    Factor("interruption_cost", "key", "cost", (0.0, INF), unit="s"),
    Factor("capacity", "site", "robot_capacity", (1, 10), integer=True),
    Factor("door_hold", "site", "door_hold_time", (1.0, 600.0), unit="s"),
    Factor("door_share", "site", "door_share", (0.0, 1.0)),
    Factor("task_std", "human", "task_std", (0.0, INF), unit="s"),
    Factor("walk_speed", "human", "walk_speed", (0.05, 5.0), unit="m/s"),
    Factor("open_time", "human", "open_time", (0.0, INF), unit="s"),
    Factor("declare_time", "human", "declare_time", (0.0, INF), unit="s"),
    Factor("decision_interval", "human", "decision_interval", (0.5, INF), unit="s"),
    Factor("no_comm_probability", "human", "no_comm_probability", (0.0, 1.0)),
    Factor("declare_probability", "human", "declare_probability", (0.0, 1.0)),
    Factor("focus_count", "human", "focus_count", (0, 20), integer=True),
    Factor("focus_fraction", "human", "focus_fraction", (0.0, 0.9)),
    Factor("focus_responsiveness", "human", "focus_responsiveness", (0.0, 1.0)),
    Factor("anticipation", "human", "anticipation", (0.0, INF), unit="s"),
)
FACTORS: dict[str, Factor] = {f.name: f for f in _FACTORS}
KEY_OPTIONS = {f.name: f.option for f in _FACTORS if f.target == "key"}


def factor(name: str) -> Factor:
    try:
        return FACTORS[name]
    except KeyError:
        raise ValueError(f"unknown factor {name!r} (known: {', '.join(FACTORS)})") from None


@dataclass
class Split:
    """A point's values by where they go."""

    key: dict[str, float] = field(default_factory=dict)  # p, task, cost
    site: dict[str, Any] = field(default_factory=dict)  # generator options
    human: dict[str, Any] = field(default_factory=dict)  # HumanConfig fields


def split(point: Mapping[str, float]) -> Split:
    out = Split()
    for name, value in sorted(point.items()):
        f = factor(name)
        typed: Any = int(round(value)) if f.integer else float(value)
        getattr(out, f.target)[f.option] = typed
    return out


def check_point(point: Mapping[str, float]) -> list[str]:
    """What is wrong with ``point`` (unknown factors, values outside their limits); empty when fine."""
    problems = []
    for name, value in point.items():
        if name not in FACTORS:
            problems.append(f"unknown factor {name!r}")
            continue
        f = FACTORS[name]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            problems.append(f"{name}: expected a number, got {value!r}")
        elif not f.limits[0] <= value <= f.limits[1]:
            problems.append(f"{name}: {value:g} is outside [{f.limits[0]:g}, {f.limits[1]:g}]")
        elif f.integer and value != round(value):
            problems.append(f"{name}: expected a whole number, got {value:g}")
        elif float(f"{value:g}") != value:  # trials.csv keeps six significant digits, and a key must read back
            problems.append(f"{name}: {value!r} has more than six significant digits")
    return problems
