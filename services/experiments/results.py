"""A results folder read back for the report: the sweep, its trials as numbers, its side files.

Only ``trials.csv`` is required. ``sweep.json`` gives the order of conditions (else the order the
CSV shows them in) and the sweep's kind (else guessed from what varies); ``timing.csv``,
``runs.json`` and ``params.json`` add the wall-clock figures and the model's parameters when present.

A sweep's **level** is the condition it varies: the team size (``robots``), the door-opening
probability (``laziness``), the pair (task length, interruption cost) (``map``), or the point
(``detour``, ``sensitivity``: the point's index; its factors name it); a ``population`` sweep has
one level, all its persons pooled (the persons are the mixed model's groups, :mod:`.mixed`). Methods are
compared **pair by pair** (:meth:`Results.pairs`): two trials pair when they share everything but
the method (``TrialKey.pair``: same site, same human draws) and both completed (``ok``) with the
metric known; a trial that failed in one method drops that pair.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from .design import METHODS, POINT_SWEEPS, SweepSpec, TrialKey, format_p
from .record import PLAN_FIELDS, POINT_FIELD, timing_fields, trial_fields
from .store import CsvStore, StoreError

METRICS = (
    "team_completion_time",
    "sum_of_times",
    "door_openings",
    "slowest_robot_time",
    "human_completion_time",
    "human_task_time",
    "human_time_away",
    "human_door_trips",
    "human_interruptions",
    "human_time_lost",
    "focus_declared",
    "feedback_sent",
    "feedback_accepted",
    "replans",
    "world_versions",
    "robot_wait_time",
    "robot_overlaps",
    "wall_contacts",
    "wall_depth_max",
    "actions_failed",
)
COUNTS = frozenset(
    {
        "robot_overlaps",
        "wall_contacts",
        "actions_failed",
        "door_openings",
        "human_door_trips",
        "human_interruptions",
        "focus_declared",
        "feedback_sent",
        "feedback_accepted",
        "replans",
        "world_versions",
        "constraint_replans",
        "plans_changed",
        "deliveries_reordered",
    }
)  # the others are times (s), but wall_depth_max (m)

# robots; door-opening probability; (task mean, interruption cost); a point's index (detour, sensitivity)
Level = int | float | tuple[float, float]
POOLED = 0  # the one level of a population sweep


class ReportError(ValueError):
    """A folder the report cannot be built from."""


class Conditioned(Protocol):
    """Anything with a trial's condition (a :class:`TrialResult` or a :class:`~.design.TrialKey`)."""

    robots: int
    p: float
    task: float
    cost: float
    point: int


def _number(text: str) -> float | None:
    return float(text) if text != "" else None


@dataclass
class TrialResult:
    method: str
    robots: int
    objects: int
    p: float
    task: float  # the human's mean task length (s)
    cost: float  # interruption cost (s)
    trial: int
    status: str
    reason: str
    values: dict[str, float | None]
    human_slowest: bool | None  # the human was the team's slowest agent
    point: int = -1
    factors: dict[str, float] = field(default_factory=dict)  # the point's factors (point sweeps)

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def key(self) -> TrialKey:
        return TrialKey(self.method, self.robots, self.objects, self.p, self.task, self.cost, self.trial, self.point)


@dataclass(frozen=True)
class Pair:
    """One trial index's value of a metric in two methods."""

    trial: int
    a: float
    b: float


@dataclass
class Results:
    folder: Path
    kind: str  # robots, laziness or map: what the sweep varies
    spec: SweepSpec | None
    trials: list[TrialResult]
    timing: list[dict[str, str]] = field(default_factory=list)
    runs: list[dict[str, Any]] = field(default_factory=list)
    params: dict[str, Any] = field(default_factory=dict)

    # ------------------------------------------------------------------ structure

    @property
    def methods(self) -> list[str]:
        present = {t.method for t in self.trials}
        order = list(self.spec.methods) if self.spec else list(METHODS)
        return [m for m in order if m in present] + sorted(present - set(order))

    @property
    def points(self) -> bool:
        return self.kind in POINT_SWEEPS

    def level_of(self, t: Conditioned) -> Level:
        if self.kind == "robots":
            return t.robots
        if self.kind == "laziness":
            return t.p
        if self.kind == "population":
            return POOLED
        if self.points:
            return t.point
        return (t.task, t.cost)

    def varied(self) -> list[str]:
        """The factors (and key columns) whose value differs between the points, in column order."""
        names = ["door_probability", "task_mean", "interruption_cost", *(self.spec.factor_names() if self.spec else ())]
        points = list(self.spec.points) if self.spec else []
        return [n for n in names if len({p.get(n) for p in points}) > 1]

    def point_factors(self, level: Level) -> dict[str, float]:
        """The factors of point ``level`` (empty when unknown)."""
        if self.spec is None or not isinstance(level, int) or not 0 <= level < len(self.spec.points):
            return {}
        return dict(self.spec.points[level])

    @property
    def levels(self) -> list[Level]:
        """The swept variable's values, in the sweep's order (team sizes, probabilities, map cells)."""
        seen = {self.level_of(t) for t in self.trials}
        if self.spec is None:
            order: list[Level] = sorted(seen)  # type: ignore[type-var]
        elif self.kind == "population":
            order = [POOLED]
        elif self.points:
            order = list(range(len(self.spec.points)))
        elif self.kind == "robots":
            order = list(self.spec.robots)
        elif self.kind == "laziness":
            order = list(self.spec.ps)
        else:
            order = [(w, c) for w in self.spec.tasks for c in self.spec.costs]
        return [v for v in order if v in seen] + sorted(seen - set(order))  # type: ignore[type-var]

    @property
    def level_columns(self) -> tuple[str, ...]:
        """The CSV columns that name a level."""
        if self.kind == "population":
            return ("persons",)
        if self.points:
            return (POINT_FIELD, *self.varied())
        return {"robots": ("robots",), "laziness": ("door_probability",)}.get(
            self.kind, ("task_mean", "interruption_cost")
        )

    def level_cells(self, level: Level) -> list[str]:
        """A level as the text of its :attr:`level_columns`."""
        if self.kind == "population":
            return ["all"]
        if self.points:
            factors = self.point_factors(level)
            return [str(level), *(format_p(factors[n]) if n in factors else "" for n in self.varied())]
        if isinstance(level, tuple):
            return [format_p(v) for v in level]
        return [str(int(level))] if self.kind == "robots" else [format_p(level)]

    def level_label(self, level: Level) -> str:
        """A level for people: ``3 robots``, ``p = 0.5``, ``task 600 s, cost 15 s``, ``capacity 2, door_share 0.5``."""
        if self.kind == "population":
            return "all persons"
        if self.points:
            factors = self.point_factors(level)
            named = ", ".join(f"{n} {format_p(factors[n])}" for n in self.varied() if n in factors)
            return named or f"point {level}"
        if isinstance(level, tuple):
            return f"task {format_p(level[0])} s, cost {format_p(level[1])} s"
        return f"{int(level)} robots" if self.kind == "robots" else f"p = {format_p(level)}"

    @property
    def variable(self) -> str:
        if self.points:
            return ", ".join(self.varied()) or "point"
        return {"robots": "robots", "laziness": "door-opening probability"}.get(
            self.kind, "task length × interruption cost"
        )

    # ------------------------------------------------------------------ values

    def values(self, method: str, level: Level, metric: str) -> list[float]:
        """``metric`` of the completed (``ok``) trials of one condition."""
        return [
            t.values[metric]
            for t in self.trials  # type: ignore[misc]
            if t.ok and t.method == method and self.level_of(t) == level and t.values.get(metric) is not None
        ]

    def pairs(self, metric: str, level: Level, a: str, b: str) -> list[Pair]:
        """``metric`` of methods ``a`` and ``b`` at the same trial index, where both completed, by trial index."""

        def known(method: str) -> dict[tuple, TrialResult]:
            return {
                t.key.pair(): t
                for t in self.trials
                if t.ok and t.method == method and self.level_of(t) == level and t.values.get(metric) is not None
            }

        mine, theirs = known(a), known(b)
        common = sorted(set(mine) & set(theirs), key=lambda k: (k[-1], k))
        return [Pair(mine[k].trial, mine[k].values[metric], theirs[k].values[metric]) for k in common]  # type: ignore[arg-type]

    def condition(self, method: str, level: Level) -> list[TrialResult]:
        return [t for t in self.trials if t.method == method and self.level_of(t) == level]

    def conditions(self) -> Iterator[tuple[Level, str, list[TrialResult]]]:
        """(level, method, trials) of every condition that has trials, in the sweep's order."""
        for level in self.levels:
            for method in self.methods:
                trials = self.condition(method, level)
                if trials:
                    yield level, method, trials


def _trial(row: dict[str, str], factors: tuple[str, ...] = ()) -> TrialResult:
    values = {name: _number(row[name]) for name in METRICS}
    values.update({name: _number(row[name]) for name in PLAN_FIELDS if name in row})
    human_slowest = None
    if row["status"] == "ok" and row["human_completion_time"] and row["slowest_robot_time"]:
        human_slowest = float(row["human_completion_time"]) >= float(row["slowest_robot_time"])
    return TrialResult(
        row["method"],
        int(row["robots"]),
        int(row["objects"]),
        float(row["door_probability"]),
        float(row["task_mean"]),
        float(row["interruption_cost"]),
        int(row["trial"]),
        row["status"],
        row["reason"],
        values,
        human_slowest,
        int(row.get(POINT_FIELD) or -1),
        {name: float(row[name]) for name in factors if row.get(name)},
    )


def _kind(spec: SweepSpec | None, trials: list[TrialResult]) -> str:
    if spec is not None:
        return spec.kind
    # Without sweep.json: whichever varies (task length or interruption cost: the map).
    if len({t.task for t in trials}) > 1 or len({t.cost for t in trials}) > 1:
        return "map"
    return "laziness" if len({t.p for t in trials}) > 1 and len({t.robots for t in trials}) == 1 else "robots"


def _json(path: Path, default: Any) -> Any:
    if not path.exists():
        return default
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ReportError(f"{path}: not JSON ({exc})") from None


def load_results(folder: Path) -> Results:
    folder = Path(folder)
    spec = None
    sweep = _json(folder / "sweep.json", None)
    if sweep is not None:
        try:
            spec = SweepSpec.from_json(sweep)
        except ValueError as exc:
            raise ReportError(f"{folder / 'sweep.json'}: {exc}") from None
    store = CsvStore(folder / "trials.csv", trial_fields(spec))
    if not store.exists():
        raise ReportError(f"{folder}: no trials.csv (not a results folder, or the sweep has not recorded a trial yet)")
    try:
        rows = store.load()
        timing = CsvStore(folder / "timing.csv", timing_fields(spec)).load()
    except StoreError as exc:
        raise ReportError(str(exc)) from None
    if not rows:
        raise ReportError(f"{folder / 'trials.csv'} has no trials yet")
    factors = spec.factor_names() if spec is not None else ()
    try:
        trials = [_trial(row, factors) for row in rows]
    except (KeyError, ValueError) as exc:
        raise ReportError(f"{folder / 'trials.csv'}: a malformed row ({exc})") from None
    runs = _json(folder / "runs.json", [])
    params = _json(folder / "params.json", {})
    return Results(folder, _kind(spec, trials), spec, trials, timing, runs, params)


def statuses(trials: list[TrialResult]) -> dict[str, int]:
    counts: dict[str, int] = {}
    for t in trials:
        counts[t.status] = counts.get(t.status, 0) + 1
    return counts


__all__ = ["COUNTS", "METRICS", "Level", "Pair", "ReportError", "Results", "TrialResult", "load_results", "statuses"]
