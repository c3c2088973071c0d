"""Fixed CSVs for the report's tests: rows written by hand, through the same store the runner uses."""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

from services.experiments.record import TRIAL_FIELDS
from services.experiments.store import CsvStore


def row(method: str, robots: int, trial: int, *, team: float | None, doors: int | None, p: float = 0.5,
        status: str = "ok", human: float | None = None, robot: float | None = None, **extra: str) -> dict[str, str]:
    """One trials.csv row with the figures the report reads; everything else empty or neutral."""
    cells = {name: "" for name in TRIAL_FIELDS}
    cells.update(method=method, robots=str(robots), objects="3", door_probability=f"{p:g}", trial=str(trial),
                 site_seed="1", seed="2", status=status)
    if team is not None:
        cells["team_completion_time"] = f"{team:.3f}"
        cells["human_completion_time"] = f"{(human if human is not None else team):.3f}"
        cells["slowest_robot_time"] = f"{(robot if robot is not None else team - 100.0):.3f}"
    if doors is not None:
        cells["door_openings"] = str(doors)
    cells.update(extra)
    return cells


def write_trials(folder: Path, rows: Iterable[dict[str, str]]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    CsvStore(folder / "trials.csv", TRIAL_FIELDS).rewrite(rows)
    return folder / "trials.csv"
