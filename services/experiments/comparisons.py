"""ARROCH against each baseline, trial by trial: which metrics are tested, with which test, against
which equivalence margin, and the verdict each (level, baseline) gets from the Holm-adjusted p-values.

The report's ``tests.csv``, the paper's claims (:mod:`.claims`) and the map's heatmaps
(:mod:`.maps`) all read the same :class:`Test` objects, so a verdict always matches the table.

**Family.** One metric's tests over every level of the sweep and every baseline. Holm's correction
runs over the family, once on the primary p-values and once on the equivalence (TOST) p-values.

**Primary test.** Times: the Wilcoxon signed-rank test (no assumption of normal differences; a
trial's time is skewed by a robot's long wait). Counts: the sign-flip permutation test on the
differences (exact for small samples, and it makes no use of ranks that counts tie all the time).
The paired t-test is reported alongside; it decides nothing. See :mod:`.stats` for each test.

**Verdict** of one (level, baseline), at ``ALPHA`` on Holm-adjusted p-values only:

- ``lower (significant)``: the primary test's Holm p < ``ALPHA`` and ARROCH's mean difference is
  negative (for the Wilcoxon test the ranks must point the same way, ``R- > R+``);
- ``higher (significant)``: the same with a positive difference (and ``R+ > R-``);
- ``equivalent within ±margin``: otherwise, when the TOST Holm p < ``ALPHA``;
- ``not significant``: otherwise; ``no data`` with fewer than two complete pairs.

**Equivalence margins** (chosen before the runs; the paper states none):

- team completion time and sum of times: ±``TIME_MARGIN`` = 30 s, 5 % of the paper-scale task
  (600 s) and half the sd of the human's task draw (60 s): a difference inside it is smaller than
  what her own task varies from trial to trial. The sum of times uses the same seconds on purpose
  (strict for a sum of four agents): "equivalent" then means neither method saves the team more
  than 30 s of anyone's time in all;
- her time away from her task: ±``AWAY_MARGIN`` = 10 s, about one door trip (walking to the door,
  opening it, walking back);
- counts (door openings): ±``COUNT_MARGIN`` = 0.5 opening per trial: less than one whole door on
  average.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from .results import COUNTS, Level, Results
from .stats import Paired, holm, paired

ALPHA = 0.05
REFERENCE = "arroch"
TIME_MARGIN = 30.0  # s, team completion time and sum of times (module docstring)
AWAY_MARGIN = 10.0  # s, the human's time away from her task
COUNT_MARGIN = 0.5  # door openings per trial


@dataclass(frozen=True)
class Metric:
    name: str  # the CSV column
    label: str  # for people
    unit: str  # "s", or "" for counts
    margin: float  # equivalence margin, in the metric's unit

    @property
    def count(self) -> bool:
        """Counts get the permutation test as primary; times, the Wilcoxon test."""
        return self.name in COUNTS

    @property
    def primary_test(self) -> str:
        return "permutation" if self.count else "wilcoxon"

    @property
    def primary_label(self) -> str:
        return "sign-flip permutation test" if self.count else "Wilcoxon signed-rank test"

    @property
    def digits(self) -> int:
        return 2 if self.count else 1

    @property
    def suffix(self) -> str:
        """The unit after a number: `` s``, or nothing for counts."""
        return f" {self.unit}" if self.unit else ""


TEAM_TIME = Metric("team_completion_time", "team completion time", "s", TIME_MARGIN)
SUM_OF_TIMES = Metric("sum_of_times", "sum of all agents' times", "s", TIME_MARGIN)
DOOR_OPENINGS = Metric("door_openings", "door openings", "", COUNT_MARGIN)
TIME_AWAY = Metric("human_time_away", "human's time away from her task", "s", AWAY_MARGIN)
TESTED = (TEAM_TIME, SUM_OF_TIMES, DOOR_OPENINGS, TIME_AWAY)

LOWER, HIGHER, NOT_SIGNIFICANT, NO_DATA = "lower (significant)", "higher (significant)", "not significant", "no data"


def equivalent(metric: Metric) -> str:
    return f"equivalent within ±{metric.margin:g}{metric.suffix}"


@dataclass(frozen=True)
class Test:
    """ARROCH against one baseline at one level of the sweep, with its family's Holm values."""

    metric: Metric
    level: Level
    baseline: str
    result: Paired
    primary_p_holm: float
    tost_p_holm: float

    @property
    def primary_p(self) -> float:
        return self.result.perm_p if self.metric.count else self.result.wilcoxon.p

    @property
    def verdict(self) -> str:
        r = self.result
        if r.n < 2:
            return NO_DATA
        if not math.isnan(self.primary_p_holm) and self.primary_p_holm < ALPHA:
            ranks_agree = self.metric.count or (r.wilcoxon.r_minus > r.wilcoxon.r_plus) == (r.mean_diff < 0)
            if r.mean_diff < 0 and ranks_agree:
                return LOWER
            if r.mean_diff > 0 and ranks_agree:
                return HIGHER
        if not math.isnan(self.tost_p_holm) and self.tost_p_holm < ALPHA:
            return equivalent(self.metric)
        return NOT_SIGNIFICANT

    def describe(self) -> str:
        """``vs no-comm: lower (significant), Δ -12.3 s [-20.1, -4.5], Holm p = 0.003``."""
        r, d = self.result, self.metric.digits
        if r.n < 2:
            return f"vs {self.baseline}: no data ({r.n} complete pair{'s' if r.n != 1 else ''})"
        return (
            f"vs {self.baseline}: {self.verdict}, Δ {r.mean_diff:+.{d}f}{self.metric.suffix} [{r.ci_low:+.{d}f}, "
            f"{r.ci_high:+.{d}f}], "
            f"{self.metric.primary_test} Holm p = {format_p_value(self.primary_p_holm)}, "
            f"TOST Holm p = {format_p_value(self.tost_p_holm)}, {r.n} pairs"
        )


def baselines(results: Results) -> list[str]:
    return [m for m in results.methods if m != REFERENCE] if REFERENCE in results.methods else []


def family(results: Results, metric: Metric) -> list[Test]:
    """``metric``'s tests at every level against every baseline, Holm-adjusted over all of them."""
    raw: list[tuple[Level, str, Paired]] = []
    for level in results.levels:
        for baseline in baselines(results):
            pairs = results.pairs(metric.name, level, REFERENCE, baseline)
            raw.append(
                (
                    level,
                    baseline,
                    paired([p.a for p in pairs], [p.b for p in pairs], margin=metric.margin, permutation=metric.count),
                )
            )
    primary = holm([(r.perm_p if metric.count else r.wilcoxon.p) for _, _, r in raw])
    equivalence = holm([r.tost_p for _, _, r in raw])
    return [
        Test(metric, level, baseline, r, hp, ht)
        for (level, baseline, r), hp, ht in zip(raw, primary, equivalence, strict=True)
    ]


def families(results: Results, metrics: Iterable[Metric] = TESTED) -> dict[str, list[Test]]:
    """Every tested metric's family, by metric name."""
    return {m.name: family(results, m) for m in metrics}


def format_p_value(p: float) -> str:
    """A p-value for people: two significant digits, scientific below 1e-4, ``n/a`` when undefined."""
    if math.isnan(p):
        return "n/a"
    return f"{p:.2g}" if p >= 1e-4 else f"{p:.1e}"
