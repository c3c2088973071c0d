"""The claims' verdicts come from Holm-adjusted p-values over each claim's family (all levels × baselines).

Paired trials with every difference of the same sign and distinct sizes make the exact Wilcoxon p
easy by hand: of the 2^n sign patterns only all-minus and all-plus are as extreme, p = 2 / 2^n.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from services.experiments.claims import Claim, check_claims
from services.experiments.comparisons import TEAM_TIME, family
from services.experiments.results import load_results
from tests.experiments.helpers import row, write_trials


def _sweep(
    folder: Path,
    n: int,
    shift: dict[tuple[str, int | float], float],
    *,
    kind: str = "robots",
    doors: dict[str, int] | None = None,
) -> Path:
    """``n`` paired trials per level: the same base time per trial index in every method (common draws),
    plus the method's shift at that level and a per-trial spread (trial i: i + 1 s) for ARROCH only, so
    every difference is distinct and has the sign of the shift."""
    rows = []
    for (method, level), delta in shift.items():
        for i in range(n):
            spread = (i + 1) * (1 if delta >= 0 else -1) if method == "arroch" and delta else 0.0
            team = 600.0 + 7.0 * i + delta + spread
            opened = (doors or {}).get(method, 5)
            if kind == "robots":
                rows.append(row(method, int(level), i, team=team, doors=opened))
            else:
                rows.append(row(method, 3, i, p=float(level), team=team, doors=opened))
    write_trials(folder, rows)
    return folder


def _claims(folder: Path) -> dict[str, Claim]:
    return {c.title: c for c in check_claims(load_results(folder))}


def test_holm_turns_an_unadjusted_significance_into_not_significant(tmp_path: Path) -> None:
    # Six pairs at each of two team sizes, ARROCH always lower: exact Wilcoxon p = 2/64 = 0.031 < 0.05 at each level,
    # but Holm over the family of two gives 2 x 0.031 = 0.0625: not significant, and the claim is not confirmed.
    folder = _sweep(tmp_path, 6, {("arroch", 2): -40, ("no-comm", 2): 0, ("arroch", 3): -40, ("no-comm", 3): 0})
    tests = family(load_results(folder), TEAM_TIME)
    assert [t.primary_p for t in tests] == pytest.approx([2 / 64, 2 / 64])
    assert [t.primary_p_holm for t in tests] == pytest.approx([4 / 64, 4 / 64])
    assert {t.verdict for t in tests} == {"not significant"}
    claims = _claims(folder)
    assert claims["Lowest team completion time"].verdict == "not confirmed"
    assert claims["Lowest sum of times"].verdict == "not confirmed"


def test_confirmed_when_every_level_survives_holm(tmp_path: Path) -> None:
    # Eight pairs: p = 2/256 each, Holm 4/256 = 0.016 < 0.05 at both levels. Door openings: ARROCH 3, no-comm 5 in
    # every pair (d = -2 always): the permutation test's p is 2/256 too.
    folder = _sweep(
        tmp_path,
        8,
        {("arroch", 2): -40, ("no-comm", 2): 0, ("arroch", 3): -40, ("no-comm", 3): 0},
        doors={"arroch": 3, "no-comm": 5},
    )
    claims = _claims(folder)
    assert {title: c.verdict for title, c in claims.items()} == {
        "Fewest door openings": "confirmed",
        "Lowest team completion time": "confirmed",
        "Lowest sum of times": "confirmed",
    }
    doors = claims["Fewest door openings"].tests
    assert [t.primary_p for t in doors] == pytest.approx([2 / 256, 2 / 256])
    assert [t.primary_p_holm for t in doors] == pytest.approx([4 / 256, 4 / 256])


def test_equal_openings_make_the_claim_equivalent(tmp_path: Path) -> None:
    # The same openings in every pair: no difference (permutation p = 1), and within ±0.5 beyond doubt (TOST p = 0).
    folder = _sweep(tmp_path, 8, {("arroch", 2): -40, ("no-comm", 2): 0, ("arroch", 3): -40, ("no-comm", 3): 0})
    claim = _claims(folder)["Fewest door openings"]
    assert claim.verdict == "equivalent"
    assert {t.verdict for t in claim.tests} == {"equivalent within ±0.5"}
    assert "0 of 2 (level, baseline) comparisons" in claim.detail


def test_one_significant_comparison_against_the_claim_contradicts_it(tmp_path: Path) -> None:
    # One level supports the claim, the other goes against it, both Holm-significant: contradicted, not "partly".
    folder = _sweep(tmp_path, 8, {("arroch", 2): -40, ("no-comm", 2): 0, ("arroch", 3): +40, ("no-comm", 3): 0})
    claim = _claims(folder)["Lowest team completion time"]
    assert claim.verdict == "contradicted"
    assert [t.verdict for t in claim.tests] == ["lower (significant)", "higher (significant)"]
    assert "3 robots: vs no-comm: higher (significant)" in claim.detail
    assert "Against it: 1 significantly higher." in claim.detail


def test_some_support_and_nothing_against_is_partly(tmp_path: Path) -> None:
    # Level 2 significantly lower; level 3 differences of both signs (not significant, and too spread for TOST).
    rows = []
    for i in range(8):
        base = 600.0 + 7.0 * i
        rows += [row("arroch", 2, i, team=base - 40 - i, doors=5), row("no-comm", 2, i, team=base, doors=5)]
        swing = (60.0 + i) * (1 if i % 2 else -1)
        rows += [row("arroch", 3, i, team=base + swing, doors=5), row("no-comm", 3, i, team=base, doors=5)]
    folder = tmp_path / "partly"
    write_trials(folder, rows)
    claim = _claims(folder)["Lowest team completion time"]
    assert [t.outcome for t in claim.tests] == ["lower (significant)", "not significant"]
    assert claim.verdict == "partly"


def test_nothing_significant_either_way_is_not_confirmed(tmp_path: Path) -> None:
    rows = []
    for i in range(8):
        swing = (60.0 + i) * (1 if i % 2 else -1)
        rows += [row("arroch", 2, i, team=600 + swing, doors=5), row("no-comm", 2, i, team=600.0, doors=5)]
    folder = tmp_path / "nothing"
    write_trials(folder, rows)
    claim = _claims(folder)["Lowest team completion time"]
    assert [t.outcome for t in claim.tests] == ["not significant"]
    assert claim.verdict == "not confirmed"


def test_a_significant_difference_inside_the_margin_says_both(tmp_path: Path) -> None:
    # ARROCH 1-8 s slower in every pair (two taps): significantly higher, and within ±30 s by TOST. The claim is
    # contradicted, and the detail says the contradiction is inside the margin.
    rows = []
    for i in range(8):
        rows += [
            row("arroch", 2, i, team=601.0 + i + 7 * i, doors=5),
            row("no-comm", 2, i, team=600.0 + 7 * i, doors=5),
        ]
    folder = tmp_path / "taps"
    write_trials(folder, rows)
    claim = _claims(folder)["Lowest team completion time"]
    (test,) = claim.tests
    assert test.outcome == "higher (significant)" and test.within_margin
    assert test.verdict == "higher (significant), within ±30 s (TOST)"
    assert claim.verdict == "contradicted"
    assert "1 of them within the equivalence margin (TOST)" in claim.detail


def test_laziness_crossover(tmp_path: Path) -> None:
    # Three probabilities x one baseline, eight pairs: p = 2/256 each, Holm 3 x 2/256 = 0.023.
    yes = _sweep(
        tmp_path / "yes",
        8,
        {
            ("arroch", 0.05): +60,
            ("no-comm", 0.05): 0,
            ("arroch", 0.1): -40,
            ("no-comm", 0.1): 0,
            ("arroch", 0.5): -80,
            ("no-comm", 0.5): 0,
        },
        kind="laziness",
    )
    claim = _claims(yes)["Laziness crossover"]
    assert claim.verdict == "confirmed"
    assert "no-comm significantly faster" in claim.detail
    assert "stays below no-comm's from p = 0.1 on" in claim.detail
    # ARROCH is fastest even for the laziest human: the paper's exception is not seen.
    no = _sweep(
        tmp_path / "no",
        8,
        {
            ("arroch", 0.05): -20,
            ("no-comm", 0.05): 0,
            ("arroch", 0.1): -40,
            ("no-comm", 0.1): 0,
            ("arroch", 0.5): -80,
            ("no-comm", 0.5): 0,
        },
        kind="laziness",
    )
    claim = _claims(no)["Laziness crossover"]
    assert claim.verdict == "contradicted"  # ARROCH significantly faster where no-comm should be
    assert "no-comm not significantly faster" in claim.detail


def test_claims_cannot_be_checked_without_a_baseline(tmp_path: Path) -> None:
    folder = _sweep(tmp_path, 4, {("arroch", 2): 0})
    assert {c.verdict for c in check_claims(load_results(folder))} == {"cannot be checked"}
