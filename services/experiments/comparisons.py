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

A significant difference that TOST also finds inside the margin is both, and says so: ``higher
(significant), within ±30 s (TOST)`` (two 1 s declarations make ARROCH reliably a little slower,
by less than anything the margin counts). :attr:`Test.outcome` is the category alone.

**Interval.** Each test's table shows the interval of the test that decides its verdict, at the
level Holm tested it at (:func:`.stats.holm_alphas`): for times the Hodges–Lehmann estimate with its
Wilcoxon interval, for counts the mean difference with its sign-flip interval. The paired t
interval stays in ``tests.csv`` (``t_ci_low``, ``t_ci_high``) for reference; it decides nothing.

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
from .stats import Interval, Paired, differences, hodges_lehmann, holm, holm_alphas, paired, sign_flip_interval

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
EQUIVALENT = "equivalent"  # the category; its text names the margin (equivalent())


def equivalent(metric: Metric) -> str:
    return f"equivalent within ±{metric.margin:g}{metric.suffix}"


@dataclass(frozen=True)
class Test:
    """ARROCH against one baseline at one level of the sweep, with its family's Holm values and the
    interval of its deciding test at its Holm level."""

    metric: Metric
    level: Level
    baseline: str
    result: Paired
    primary_p_holm: float
    tost_p_holm: float
    interval: Interval | None = None

    @property
    def primary_p(self) -> float:
        return self.result.perm_p if self.metric.count else self.result.wilcoxon.p

    @property
    def outcome(self) -> str:
        """LOWER, HIGHER, EQUIVALENT, NOT_SIGNIFICANT or NO_DATA (module docstring)."""
        r = self.result
        if r.n < 2:
            return NO_DATA
        if not math.isnan(self.primary_p_holm) and self.primary_p_holm < ALPHA:
            ranks_agree = self.metric.count or (r.wilcoxon.r_minus > r.wilcoxon.r_plus) == (r.mean_diff < 0)
            if r.mean_diff < 0 and ranks_agree:
                return LOWER
            if r.mean_diff > 0 and ranks_agree:
                return HIGHER
        return EQUIVALENT if self.within_margin else NOT_SIGNIFICANT

    @property
    def within_margin(self) -> bool:
        """TOST (Holm) puts the difference inside the equivalence margin."""
        return not math.isnan(self.tost_p_holm) and self.tost_p_holm < ALPHA

    @property
    def verdict(self) -> str:
        outcome = self.outcome
        if outcome == EQUIVALENT:
            return equivalent(self.metric)
        if outcome in (LOWER, HIGHER) and self.within_margin:
            return f"{outcome}, within ±{self.metric.margin:g}{self.metric.suffix} (TOST)"
        return outcome

    def interval_text(self) -> str:
        """``-12.3 [-20.1, -4.5]`` (the deciding test's estimate and interval), ``n/a`` without one."""
        i, d = self.interval, self.metric.digits
        if i is None or math.isnan(i.estimate):
            return "n/a"

        def bound(v: float) -> str:
            return "−∞" if v == -math.inf else "+∞" if v == math.inf else f"{v:+.{d}f}"

        return f"{i.estimate:+.{d}f} [{bound(i.low)}, {bound(i.high)}]"

    def describe(self) -> str:
        """``vs no-comm: lower (significant), HL Δ -12.3 s [-20.1, -4.5] (Wilcoxon interval at 98.8 %), ...``."""
        r = self.result
        if r.n < 2:
            return f"vs {self.baseline}: no data ({r.n} complete pair{'s' if r.n != 1 else ''})"
        return (
            f"vs {self.baseline}: {self.verdict}, {interval_label(self.metric, short=True)} "
            f"{self.interval_text()}{self.metric.suffix}{level_text(self)}, "
            f"{self.metric.primary_test} Holm p = {format_p_value(self.primary_p_holm)}, "
            f"TOST Holm p = {format_p_value(self.tost_p_holm)}, {r.n} pairs"
        )


def interval_label(metric: Metric, short: bool = False) -> str:
    """What a test's interval is, for a table's header (module docstring)."""
    if metric.count:
        return "mean Δ" if short else "mean Δ [sign-flip interval, Holm level]"
    return "HL Δ" if short else "Hodges–Lehmann Δ [Wilcoxon interval, Holm level]"


def level_text(test: Test) -> str:
    i = test.interval
    return "" if i is None or math.isnan(i.level) else f" (at {100 * i.level:.4g} %)"


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
    primaries = [(r.perm_p if metric.count else r.wilcoxon.p) for _, _, r in raw]
    primary = holm(primaries)
    equivalence = holm([r.tost_p for _, _, r in raw])
    alphas = holm_alphas(primaries, ALPHA)
    intervals = []
    for (level, baseline, _), a in zip(raw, alphas, strict=True):
        pairs = results.pairs(metric.name, level, REFERENCE, baseline)
        d = differences([p.a for p in pairs], [p.b for p in pairs])
        intervals.append(sign_flip_interval(d, a) if metric.count else hodges_lehmann(d, a))
    return [
        Test(metric, level, baseline, r, hp, ht, interval)
        for (level, baseline, r), hp, ht, interval in zip(raw, primary, equivalence, intervals, strict=True)
    ]


def families(results: Results, metrics: Iterable[Metric] = TESTED) -> dict[str, list[Test]]:
    """Every tested metric's family, by metric name."""
    return {m.name: family(results, m) for m in metrics}


def format_p_value(p: float) -> str:
    """A p-value for people: two significant digits, scientific below 1e-4, ``n/a`` when undefined."""
    if math.isnan(p):
        return "n/a"
    return f"{p:.2g}" if p >= 1e-4 else f"{p:.1e}"
