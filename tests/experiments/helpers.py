"""Fixed CSVs for the report's tests: rows written by hand, through the same store the runner uses,
and Student's t computed without scipy (to check the report's statistics independently)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

from services.experiments.record import TRIAL_FIELDS
from services.experiments.store import CsvStore

# Student t, 97.5 % quantiles (tables): degrees of freedom -> t
T_975 = {3: 3.182446305284263, 4: 2.7764451051977987, 5: 2.570581835636314}


def row(
    method: str,
    robots: int,
    trial: int,
    *,
    team: float | None,
    doors: int | None,
    p: float = 0.5,
    task: float = 600.0,
    cost: float = 0.0,
    status: str = "ok",
    human: float | None = None,
    robot: float | None = None,
    total: float | None = None,
    **extra: str,
) -> dict[str, str]:
    """One trials.csv row with the figures the report reads; everything else empty or neutral.

    Unless given, the human finishes at ``team``, every robot 100 s earlier, and the sum of times is
    the human's plus each robot's."""
    cells = {name: "" for name in TRIAL_FIELDS}
    cells.update(
        method=method,
        robots=str(robots),
        objects="3",
        door_probability=f"{p:g}",
        task_mean=f"{task:g}",
        interruption_cost=f"{cost:g}",
        trial=str(trial),
        site_seed="1",
        seed="2",
        status=status,
    )
    if team is not None:
        human_time = human if human is not None else team
        robot_time = robot if robot is not None else team - 100.0
        cells["team_completion_time"] = f"{team:.3f}"
        cells["human_completion_time"] = f"{human_time:.3f}"
        cells["slowest_robot_time"] = f"{robot_time:.3f}"
        cells["sum_of_times"] = f"{(total if total is not None else human_time + robots * robot_time):.3f}"
    if doors is not None:
        cells["door_openings"] = str(doors)
    cells.update(extra)
    return cells


def write_trials(folder: Path, rows: Iterable[dict[str, str]]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    CsvStore(folder / "trials.csv", TRIAL_FIELDS).rewrite(rows)
    return folder / "trials.csv"


def t_upper_tail(t: float, df: float) -> float:
    """P(T > t) of Student's t with ``df`` degrees of freedom, from the regularized incomplete beta
    I_x(df/2, 1/2) at x = df/(df + t²), integrated with Simpson's rule (independent of scipy)."""
    a, b = df / 2, 0.5
    x = df / (df + t * t)
    n = 20000
    h = x / n
    log_beta = math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b)

    def f(u: float) -> float:
        return 0.0 if u == 0.0 else math.exp((a - 1) * math.log(u) + (b - 1) * math.log(1 - u) - log_beta)

    two_sided = (f(0.0) + f(x) + sum((4 if i % 2 else 2) * f(i * h) for i in range(1, n))) * h / 3
    return two_sided / 2 if t >= 0 else 1 - two_sided / 2


def t_two_sided(t: float, df: float) -> float:
    return 2 * t_upper_tail(abs(t), df)
