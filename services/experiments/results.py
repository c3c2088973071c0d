"""A results folder read back for the report: the sweep, its trials as numbers, its side files.

Only ``trials.csv`` is required. ``sweep.json`` gives the order of conditions (else the order the
CSV shows them in) and the sweep's kind (else guessed from what varies); ``timing.csv``,
``runs.json`` and ``params.json`` add the wall-clock figures and the model's parameters when present.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

from .design import METHODS, SweepSpec
from .record import TIMING_FIELDS, TRIAL_FIELDS
from .store import CsvStore, StoreError

METRICS = ("team_completion_time", "door_openings", "slowest_robot_time", "human_completion_time",
           "feedback_sent", "feedback_accepted", "replans", "world_versions", "robot_wait_time", "human_time_away")


class ReportError(ValueError):
    """A folder the report cannot be built from."""


def _number(text: str) -> float | None:
    return float(text) if text != "" else None


@dataclass
class TrialResult:
    method: str
    robots: int
    objects: int
    p: float
    trial: int
    status: str
    reason: str
    values: dict[str, float | None]
    human_slowest: bool | None  # the human was the team's slowest agent

    @property
    def ok(self) -> bool:
        return self.status == "ok"


@dataclass
class Results:
    folder: Path
    kind: str  # robots or laziness: what the sweep varies
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
    def levels(self) -> list[float]:
        """The swept variable's values, in the sweep's order (team sizes, or probabilities)."""
        if self.kind == "robots":
            seen = {t.robots for t in self.trials}
            order = list(self.spec.robots) if self.spec else sorted(seen)
        else:
            seen = {t.p for t in self.trials}
            order = list(self.spec.ps) if self.spec else sorted(seen)
        return [v for v in order if v in seen] + sorted(seen - set(order))

    def level_of(self, t: TrialResult) -> float:
        return t.robots if self.kind == "robots" else t.p

    def values(self, method: str, level: float, metric: str) -> list[float]:
        """``metric`` of the completed (``ok``) trials of one condition."""
        return [t.values[metric] for t in self.trials  # type: ignore[misc]
                if t.ok and t.method == method and self.level_of(t) == level and t.values.get(metric) is not None]

    def condition(self, method: str, level: float) -> list[TrialResult]:
        return [t for t in self.trials if t.method == method and self.level_of(t) == level]

    def conditions(self) -> Iterator[tuple[float, str, list[TrialResult]]]:
        """(level, method, trials) of every condition that has trials, in the sweep's order."""
        for level in self.levels:
            for method in self.methods:
                trials = self.condition(method, level)
                if trials:
                    yield level, method, trials

    @property
    def variable(self) -> str:
        return "robots" if self.kind == "robots" else "door-opening probability"


def _trial(row: dict[str, str]) -> TrialResult:
    values = {name: _number(row[name]) for name in METRICS}
    human_slowest = None
    if row["status"] == "ok" and row["human_completion_time"] and row["slowest_robot_time"]:
        human_slowest = float(row["human_completion_time"]) >= float(row["slowest_robot_time"])
    return TrialResult(row["method"], int(row["robots"]), int(row["objects"]), float(row["door_probability"]),
                       int(row["trial"]), row["status"], row["reason"], values, human_slowest)


def _kind(spec: SweepSpec | None, trials: list[TrialResult]) -> str:
    if spec is not None:
        return spec.kind
    # Without sweep.json: whichever of team size and probability varies.
    return "laziness" if len({t.p for t in trials}) > 1 and len({t.robots for t in trials}) == 1 else "robots"


def load_results(folder: Path) -> Results:
    folder = Path(folder)
    store = CsvStore(folder / "trials.csv", TRIAL_FIELDS)
    if not store.exists():
        raise ReportError(f"{folder}: no trials.csv (not a results folder, or the sweep has not recorded a trial yet)")
    try:
        rows = store.load()
        timing = CsvStore(folder / "timing.csv", TIMING_FIELDS).load()
    except StoreError as exc:
        raise ReportError(str(exc)) from None
    if not rows:
        raise ReportError(f"{folder / 'trials.csv'} has no trials yet")
    try:
        trials = [_trial(row) for row in rows]
    except (KeyError, ValueError) as exc:
        raise ReportError(f"{folder / 'trials.csv'}: a malformed row ({exc})") from None
    spec = None
    if (folder / "sweep.json").exists():
        try:
            spec = SweepSpec.from_json(json.loads((folder / "sweep.json").read_text(encoding="utf-8")))
        except (json.JSONDecodeError, ValueError) as exc:
            raise ReportError(f"{folder / 'sweep.json'}: {exc}") from None
    runs = json.loads((folder / "runs.json").read_text(encoding="utf-8")) if (folder / "runs.json").exists() else []
    params = json.loads((folder / "params.json").read_text(encoding="utf-8")) if (folder / "params.json").exists() else {}
    return Results(folder, _kind(spec, trials), spec, trials, timing, runs, params)


def statuses(trials: list[TrialResult]) -> dict[str, int]:
    counts: dict[str, int] = {}
    for t in trials:
        counts[t.status] = counts.get(t.status, 0) + 1
    return counts


__all__ = ["METRICS", "ReportError", "Results", "TrialResult", "load_results", "statuses"]
