"""The paper's claims (§V-A) checked against a sweep's numbers.

- **Fewest door openings** (figure "different number of robots" (a), and "human laziness" (a)):
  at every level of the sweep, ARROCH's mean number of door openings is below each baseline's.
- **Lowest team completion time** (figure "different number of robots" (b)): at every team size,
  ARROCH's mean team completion time is below each baseline's.
- **Laziness crossover** (figure "human laziness" (b)): ARROCH has the lowest team completion time
  "except for situations where the door opening probability is very low" — as long as the human
  opens with probability >= 0.1 — while no-comm, whose human walks to the door every minute
  whatever she sees, is faster when she is very lazy.

A level counts as *confirmed* when ARROCH's mean is lower than each baseline's and Welch's test
finds each difference significant at ``ALPHA`` (two-sided); *lower, not significant* when the means
are lower but a test is not; *not confirmed* otherwise. A claim over all levels is confirmed only if
every level is; Holm's correction over all the claim's tests is shown as well.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from .results import Results
from .stats import Comparison, compare, holm

ALPHA = 0.05
COOPERATIVE_P = 0.1  # the paper's caption: ARROCH is best "as long as ... >= 0.1 probability"
REFERENCE = "arroch"
BASELINE_FOR_CROSSOVER = "no-comm"


@dataclass
class LevelCheck:
    level: float
    verdict: str  # confirmed, lower, not confirmed, no data
    comparisons: dict[str, Comparison] = field(default_factory=dict)  # baseline -> ARROCH vs it
    holm_p: dict[str, float] = field(default_factory=dict)


@dataclass
class Claim:
    title: str
    statement: str
    verdict: str  # confirmed, partly confirmed, not confirmed, cannot be checked
    detail: str
    levels: list[LevelCheck] = field(default_factory=list)


def _fmt_level(results: Results, level: float) -> str:
    return f"{int(level)} robots" if results.kind == "robots" else f"p = {level:g}"


def _level_check(results: Results, level: float, metric: str, baselines: list[str]) -> LevelCheck:
    ref = results.values(REFERENCE, level, metric)
    check = LevelCheck(level, "no data")
    for baseline in baselines:
        other = results.values(baseline, level, metric)
        if len(ref) < 2 or len(other) < 2:
            return check
        check.comparisons[baseline] = compare(ref, other)
    lower = all(c.mean_a < c.mean_b for c in check.comparisons.values())
    significant = all(not math.isnan(c.welch_p) and c.welch_p < ALPHA for c in check.comparisons.values())
    check.verdict = "confirmed" if lower and significant else ("lower" if lower else "not confirmed")
    return check


def _apply_holm(checks: list[LevelCheck]) -> None:
    cells = [(check, baseline) for check in checks for baseline in check.comparisons]
    adjusted = holm([check.comparisons[b].welch_p for check, b in cells])
    for (check, baseline), p in zip(cells, adjusted):
        check.holm_p[baseline] = p


def lowest_everywhere(results: Results, metric: str, title: str, statement: str) -> Claim:
    """ARROCH's mean ``metric`` below each baseline's at every level of the sweep."""
    baselines = [m for m in results.methods if m != REFERENCE]
    if REFERENCE not in results.methods or not baselines:
        return Claim(title, statement, "cannot be checked", "the sweep needs ARROCH and at least one baseline")
    checks = [_level_check(results, level, metric, baselines) for level in results.levels]
    _apply_holm(checks)
    verdicts = [c.verdict for c in checks]
    confirmed = [c for c in checks if c.verdict == "confirmed"]
    if all(v == "confirmed" for v in verdicts):
        verdict = "confirmed"
    elif confirmed or any(v == "lower" for v in verdicts):
        verdict = "partly confirmed"
    elif all(v == "no data" for v in verdicts):
        verdict = "cannot be checked"
    else:
        verdict = "not confirmed"
    parts = []
    for check in checks:
        tests = ", ".join(f"vs {b}: {c.mean_a:.1f} vs {c.mean_b:.1f}, Welch p = {format_p_value(c.welch_p)}, MWU p = {format_p_value(c.mwu_p)}"
                          for b, c in check.comparisons.items())
        parts.append(f"{_fmt_level(results, check.level)}: {check.verdict}" + (f" ({tests})" if tests else ""))
    return Claim(title, statement, verdict, "; ".join(parts) + ".", checks)


def crossover(results: Results) -> Claim:
    """No-comm faster than ARROCH at the lowest probability; ARROCH fastest from 0.1 on."""
    title = "Laziness crossover"
    statement = ("ARROCH has the lowest team completion time as long as the human opens the door with probability "
                 f">= {COOPERATIVE_P:g}; at very low probabilities no-comm is faster.")
    if results.kind != "laziness":
        return Claim(title, statement, "cannot be checked", "needs the laziness sweep")
    methods = results.methods
    if REFERENCE not in methods or BASELINE_FOR_CROSSOVER not in methods:
        return Claim(title, statement, "cannot be checked", "the sweep needs arroch and no-comm")
    levels = results.levels
    lowest = min(levels)
    metric = "team_completion_time"
    low = results.values(REFERENCE, lowest, metric), results.values(BASELINE_FOR_CROSSOVER, lowest, metric)
    if len(low[0]) < 2 or len(low[1]) < 2:
        return Claim(title, statement, "cannot be checked", f"too few completed trials at p = {lowest:g}")
    at_low = compare(*low)
    nocomm_faster = at_low.mean_a > at_low.mean_b and at_low.welch_p < ALPHA
    baselines = [m for m in methods if m != REFERENCE]
    cooperative = [_level_check(results, level, metric, baselines) for level in levels if level >= COOPERATIVE_P]
    _apply_holm(cooperative)
    best_when_cooperative = all(c.verdict in ("confirmed", "lower") for c in cooperative) and bool(cooperative)
    # Where ARROCH's mean moves below no-comm's and stays there.
    signs = [(level, results.values(REFERENCE, level, metric), results.values(BASELINE_FOR_CROSSOVER, level, metric))
             for level in sorted(levels)]
    ahead = [(level, sum(a) / len(a) < sum(b) / len(b)) for level, a, b in signs if a and b]
    crossing = None
    for i, (level, better) in enumerate(ahead):
        if better and all(b for _, b in ahead[i:]):
            crossing = level
            break
    if nocomm_faster and best_when_cooperative:
        verdict = "confirmed"
    elif nocomm_faster or best_when_cooperative:
        verdict = "partly confirmed"
    else:
        verdict = "not confirmed"
    detail = (f"at p = {lowest:g}: ARROCH {at_low.mean_a:.1f} s vs no-comm {at_low.mean_b:.1f} s "
              f"(Welch p = {format_p_value(at_low.welch_p)}, MWU p = {format_p_value(at_low.mwu_p)}): "
              f"{'no-comm significantly faster' if nocomm_faster else 'no-comm not significantly faster'}; "
              f"from p = {COOPERATIVE_P:g} on: ARROCH "
              f"{'lowest mean at every level' if best_when_cooperative else 'not the lowest mean at every level'} ("
              + "; ".join(f"p = {c.level:g}: {c.verdict}" for c in cooperative) + "); "
              + (f"ARROCH's mean stays below no-comm's from p = {crossing:g} on." if crossing is not None
                 else "ARROCH's mean never stays below no-comm's."))
    check_low = LevelCheck(lowest, "no-comm faster" if nocomm_faster else "not confirmed", {BASELINE_FOR_CROSSOVER: at_low})
    return Claim(title, statement, verdict, detail, [check_low, *cooperative])


def check_claims(results: Results) -> list[Claim]:
    """The claims this sweep can speak to, in the paper's order."""
    where = "at every team size" if results.kind == "robots" else "at every door-opening probability"
    claims = [lowest_everywhere(results, "door_openings", "Fewest door openings",
                                f"ARROCH needs the fewest door openings by the human {where}.")]
    if results.kind == "robots":
        claims.append(lowest_everywhere(results, "team_completion_time", "Lowest team completion time",
                                        "ARROCH gives the lowest team completion time (slowest agent) at every team size."))
    else:
        claims.append(crossover(results))
    return claims


def format_p_value(p: float) -> str:
    """A p-value for people: two significant digits, scientific below 1e-4, ``n/a`` when undefined."""
    if math.isnan(p):
        return "n/a"
    return f"{p:.2g}" if p >= 1e-4 else f"{p:.1e}"
