"""The paper's claims (§V-A) checked against a sweep's numbers, pair by pair, on Holm-adjusted p-values.

- **Fewest door openings** (figures "different number of robots" (a) and "human laziness" (a)):
  at every level of the sweep ARROCH's human opens fewer doors than each baseline's.
- **Lowest team completion time** (figure "different number of robots" (b)): at every team size
  ARROCH's team completion time (slowest agent) is below each baseline's.
- **Laziness crossover** (figure "human laziness" (b)): ARROCH has the lowest team completion time
  "as long as" the human opens with probability >= 0.1, while no-comm, whose human walks to the
  door every minute whatever she sees, is faster when she is very lazy (the sweep's lowest
  probability, below 0.1).
- **Lowest sum of times** (the paper's real-world measure, "we sum up the team agents' individual
  completion times"): at every level ARROCH's sum of all agents' completion times is below each
  baseline's.

Each (level, baseline) gets the verdict of :class:`~.comparisons.Test` (primary test: Wilcoxon
signed-rank for times, the sign-flip permutation test for counts; Holm over the claim's family:
all levels × baselines of its metric, the same family as ``tests.csv``). A claim is worded as the
tests give it:

- *confirmed* when every comparison supports it (each ``lower (significant)``);
- *contradicted* when any Holm-significant comparison goes against it (``higher (significant)``;
  the detail says which, and whether TOST puts them inside the equivalence margin);
- *equivalent* when every comparison is equivalent within the margin (TOST, Holm);
- *partly* otherwise, when some comparison supports it;
- *not confirmed* when none supports it and none goes against it (not significant, or a mix of
  not significant and equivalent): the tests say nothing either way, which is not "partly";
- *cannot be checked* when the sweep lacks ARROCH, a baseline, or complete pairs.

The crossover has two halves, no-comm significantly faster at the lowest probability and ARROCH
significantly lowest against every baseline from 0.1 on: confirmed when both hold, contradicted
when a Holm-significant comparison goes against either (ARROCH significantly faster than no-comm
at the lowest probability, or significantly slower from 0.1 on), partly when some part holds, not
confirmed otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .comparisons import (
    DOOR_OPENINGS,
    EQUIVALENT,
    HIGHER,
    LOWER,
    NO_DATA,
    REFERENCE,
    SUM_OF_TIMES,
    TEAM_TIME,
    Metric,
    Test,
    baselines,
    families,
)
from .results import Results

COOPERATIVE_P = 0.1  # the paper's caption: ARROCH is best "as long as ... >= 0.1 probability"
BASELINE_FOR_CROSSOVER = "no-comm"
CONFIRMED, CONTRADICTED, EQUIVALENT_CLAIM, PARTLY, NOT_CONFIRMED, CANNOT = (
    "confirmed",
    "contradicted",
    "equivalent",
    "partly",
    "not confirmed",
    "cannot be checked",
)


@dataclass
class Claim:
    title: str
    statement: str
    verdict: str  # one of CONFIRMED, CONTRADICTED, EQUIVALENT_CLAIM, PARTLY, NOT_CONFIRMED, CANNOT
    detail: str
    tests: list[Test] = field(default_factory=list)


def label(supports: list[bool], against: list[bool], equivalent: list[bool]) -> str:
    """A claim's label from its comparisons (module docstring): each list holds one flag per comparison
    with data; ``supports`` significant in the claim's direction, ``against`` significant against it,
    ``equivalent`` TOST-equivalent within the margin."""
    if not supports:
        return CANNOT
    if all(supports):
        return CONFIRMED
    if any(against):
        return CONTRADICTED
    if all(equivalent):
        return EQUIVALENT_CLAIM
    return PARTLY if any(supports) else NOT_CONFIRMED


def _against(tests: list[Test]) -> str:
    """The comparisons that go against a claim, and whether they lie inside the margin."""
    higher = [t for t in tests if t.outcome == HIGHER]
    if not higher:
        return ""
    inside = sum(t.within_margin for t in higher)
    return (
        f" Against it: {len(higher)} significantly higher"
        + (f", {inside} of them within the equivalence margin (TOST)" if inside else "")
        + "."
    )


def _tally(tests: list[Test]) -> str:
    counts: dict[str, int] = {}
    for t in tests:
        counts[t.verdict] = counts.get(t.verdict, 0) + 1
    return ", ".join(f"{n} {v}" for v, n in counts.items())


def _flags(tests: list[Test]) -> tuple[list[bool], list[bool], list[bool]]:
    known = [t for t in tests if t.outcome != NO_DATA]
    return (
        [t.outcome == LOWER for t in known],
        [t.outcome == HIGHER for t in known],
        [t.outcome == EQUIVALENT or (t.outcome == HIGHER and t.within_margin) for t in known],
    )


def _by_level(results: Results, tests: list[Test]) -> str:
    parts = []
    for level in results.levels:
        mine = [t for t in tests if t.level == level]
        if mine:
            parts.append(f"{results.level_label(level)}: " + "; ".join(t.describe() for t in mine))
    return ". ".join(parts) + "."


def lowest_everywhere(results: Results, tests: list[Test], metric: Metric, title: str, statement: str) -> Claim:
    """ARROCH significantly lower than each baseline at every level (module docstring)."""
    if not baselines(results):
        return Claim(title, statement, CANNOT, "the sweep needs ARROCH and at least one baseline")
    supports, against, within = _flags(tests)
    verdict = label(supports, against, within)
    detail = (
        f"{sum(supports)} of {len(tests)} (level, baseline) comparisons of the {metric.label} are lower (significant) "
        f"({_tally(tests)}).{_against(tests)} {_by_level(results, tests)}"
    )
    return Claim(title, statement, verdict, detail, tests)


def _crossing(tests: list[Test]) -> str:
    """Where ARROCH's mean difference to no-comm turns negative and stays so (descriptive)."""
    ahead = [(t.level, t.result.mean_diff < 0) for t in sorted(tests, key=lambda t: t.level) if t.result.n >= 2]  # type: ignore[arg-type, return-value]
    for i, (level, better) in enumerate(ahead):
        if better and all(b for _, b in ahead[i:]):
            return f"ARROCH's mean stays below no-comm's from p = {level:g} on."
    return "ARROCH's mean never stays below no-comm's."


def crossover(results: Results, tests: list[Test]) -> Claim:
    """No-comm significantly faster than ARROCH at the lowest probability; ARROCH significantly lowest from 0.1 on."""
    title = "Laziness crossover"
    statement = (
        "ARROCH has the lowest team completion time as long as the human opens the door with probability "
        f">= {COOPERATIVE_P:g}; at very low probabilities no-comm is faster."
    )
    if results.kind != "laziness":
        return Claim(title, statement, CANNOT, "needs the laziness sweep")
    if REFERENCE not in results.methods or BASELINE_FOR_CROSSOVER not in results.methods:
        return Claim(title, statement, CANNOT, "the sweep needs arroch and no-comm")
    lowest = min(results.levels)  # type: ignore[type-var]
    nocomm = [t for t in tests if t.baseline == BASELINE_FOR_CROSSOVER]
    at_low = next(t for t in nocomm if t.level == lowest)
    cooperative = [t for t in tests if t.level >= COOPERATIVE_P]  # type: ignore[operator]
    if lowest >= COOPERATIVE_P or at_low.outcome == NO_DATA:  # type: ignore[operator]
        return Claim(
            title,
            statement,
            CANNOT,
            f"needs complete pairs at a probability below {COOPERATIVE_P:g} (lowest: {lowest:g})",
            tests,
        )
    # The first half is supported by ARROCH significantly *higher* there (no-comm faster), contradicted by lower.
    known = [t for t in cooperative if t.outcome != NO_DATA]
    supports = [at_low.outcome == HIGHER, *(t.outcome == LOWER for t in known)]
    against = [at_low.outcome == LOWER, *(t.outcome == HIGHER for t in known)]
    verdict = label(supports, against, [False] * len(supports))
    nocomm_faster = supports[0]
    lowest_after = supports[1:]
    detail = (
        f"at p = {lowest:g}, ARROCH − baseline {at_low.describe()}: "
        f"{'no-comm significantly faster' if nocomm_faster else 'no-comm not significantly faster'}; "
        f"from p = {COOPERATIVE_P:g} on: {sum(lowest_after)} of {len(lowest_after)} (level, baseline) comparisons "
        f"lower (significant) ({_tally(cooperative)}).{_against(cooperative)} {_by_level(results, cooperative)} "
        f"{_crossing(nocomm)}"
    )
    return Claim(title, statement, verdict, detail, [at_low, *cooperative])


def check_claims(results: Results, tested: dict[str, list[Test]] | None = None) -> list[Claim]:
    """The claims this sweep can speak to, in the paper's order; ``tested``: :func:`.comparisons.families`
    already computed for ``results`` (else computed here)."""
    tested = tested if tested is not None else families(results, (DOOR_OPENINGS, TEAM_TIME, SUM_OF_TIMES))
    where = {
        "robots": "at every team size",
        "laziness": "at every door-opening probability",
        "map": "in every cell of task length × interruption cost",
        "population": "over the population of simulated people",
    }.get(results.kind, f"at every point ({results.variable})")
    claims = [
        lowest_everywhere(
            results,
            tested[DOOR_OPENINGS.name],
            DOOR_OPENINGS,
            "Fewest door openings",
            f"ARROCH needs the fewest door openings by the human {where}.",
        )
    ]
    if results.kind == "laziness":
        claims.append(crossover(results, tested[TEAM_TIME.name]))
    else:
        claims.append(
            lowest_everywhere(
                results,
                tested[TEAM_TIME.name],
                TEAM_TIME,
                "Lowest team completion time",
                f"ARROCH gives the lowest team completion time (slowest agent) {where}.",
            )
        )
    claims.append(
        lowest_everywhere(
            results,
            tested[SUM_OF_TIMES.name],
            SUM_OF_TIMES,
            "Lowest sum of times",
            f"ARROCH gives the lowest sum of all agents' completion times (the paper's real-world measure) {where}.",
        )
    )
    return claims
