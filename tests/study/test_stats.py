"""The study's statistics against scipy and against their definitions computed the long way."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import stats as st

from services.study.stats import (
    EXACT_MAX,
    clopper_pearson,
    correct_family,
    hodges_lehmann,
    holm,
    paired,
    paired_t,
    poisson_ci,
    sd_ci,
    signed_rank,
)


def _flips_p(d: np.ndarray) -> float:
    """The exact conditional p by enumerating every sign pattern of the nonzero differences' mid-ranks."""
    nz = d[d != 0]
    ranks = st.rankdata(np.abs(nz))
    observed = ranks[nz > 0].sum()
    centre = ranks.sum() / 2
    hits = 0
    for signs in itertools.product((0, 1), repeat=len(nz)):
        hits += abs(float(np.dot(signs, ranks)) - centre) >= abs(observed - centre) - 1e-9
    return hits / 2 ** len(nz)


@pytest.mark.parametrize("n", [5, 8, 13, 20])
def test_signed_rank_without_ties_is_scipys_exact_test(n: int) -> None:
    rng = np.random.default_rng(n)
    for _ in range(5):
        d = rng.normal(0.4, 1.0, size=n)
        ours = signed_rank(d)
        theirs = st.wilcoxon(d, method="exact")
        assert ours.method == "exact"
        assert ours.p == pytest.approx(theirs.pvalue, rel=1e-9)
        assert ours.w == pytest.approx(theirs.statistic)


def test_signed_rank_with_ties_and_zeros_is_the_exact_conditional_test() -> None:
    rng = np.random.default_rng(1)
    for _ in range(20):
        d = rng.integers(-2, 4, size=11).astype(float)  # Likert-like: many ties and zeros
        if not np.any(d):
            continue
        ours = signed_rank(d)
        assert ours.n_nonzero == np.count_nonzero(d)
        assert ours.p == pytest.approx(_flips_p(d), abs=1e-12)


def test_signed_rank_large_samples_use_the_normal_approximation() -> None:
    d = np.random.default_rng(2).normal(0.1, 1.0, size=EXACT_MAX + 50)
    ours = signed_rank(d)
    theirs = st.wilcoxon(d, method="asymptotic", correction=False)
    assert ours.method == "normal"
    assert ours.p == pytest.approx(theirs.pvalue, rel=1e-6)


def test_signed_rank_edge_cases() -> None:
    assert math.isnan(signed_rank([1.0]).p)
    assert signed_rank([0.0, 0.0, 0.0]).p == 1.0
    assert signed_rank([0.0, 0.0, -2.0]).p == 1.0  # one nonzero difference: both signs are as extreme


def test_hodges_lehmann_is_the_median_of_walsh_averages() -> None:
    # Walsh averages of 1, 2, 4: 1, 1.5, 2.5, 2, 3, 4 -> median (2 + 2.5) / 2.
    assert hodges_lehmann([1.0, 2.0, 4.0]) == 2.25
    d = np.random.default_rng(3).normal(size=15)
    assert hodges_lehmann(d + 7.0) == pytest.approx(hodges_lehmann(d) + 7.0)


def test_paired_t_is_scipys_and_undefined_without_spread() -> None:
    rng = np.random.default_rng(4)
    a, b = rng.normal(size=9), rng.normal(size=9)
    t, p = paired_t(a, b)
    ref = st.ttest_rel(a, b)
    assert (t, p) == pytest.approx((ref.statistic, ref.pvalue))
    assert all(math.isnan(x) for x in paired_t([1.0, 2.0, 3.0], [0.0, 1.0, 2.0]))


def test_holm() -> None:
    # sorted 0.01, 0.03, 0.04 -> 3 x 0.01, max(0.03, 2 x 0.03), max(0.06, 1 x 0.04)
    assert holm([0.04, 0.01, 0.03]) == pytest.approx([0.06, 0.03, 0.06])
    out = holm([0.2, float("nan"), 0.01])
    assert out[0] == pytest.approx(0.2) and math.isnan(out[1]) and out[2] == pytest.approx(0.02)
    assert holm([0.5, 0.9]) == [1.0, 1.0]


def test_decisions_follow_the_corrected_p() -> None:
    up = paired("Q2", "likert", "arroch", "map", [5.0] * 8, [3.0] * 8)
    down = paired("t", "times", "arroch", "map", [1.0, 2, 3, 4, 5, 6, 7, 8], [3.0, 4, 5, 6, 7, 8, 9, 10])
    same = paired("Q1", "likert", "arroch", "map", [4.0] * 8, [4.0] * 8)
    few = paired("Q3", "likert", "arroch", "map", [4.0], [2.0])
    results = correct_family([up, down, same, few])
    assert results[0].decision == "higher in arroch than in map at α=0.05 after Holm"
    assert results[1].decision == "lower in arroch than in map at α=0.05 after Holm"
    assert results[2].decision == "no difference detected"
    assert results[3].decision.startswith("not tested")
    # Holm over the three tests that exist: the smallest p times 3.
    assert results[0].p_holm == pytest.approx(min(1.0, 3 * min(up.wilcoxon.p, down.wilcoxon.p)))


def test_intervals_meet_their_defining_tail_probabilities() -> None:
    k, n = 7, 40
    est = clopper_pearson(k, n)
    assert est.value == k / n
    assert st.binom.sf(k - 1, n, est.low) == pytest.approx(0.025)
    assert st.binom.cdf(k, n, est.high) == pytest.approx(0.025)
    rate = poisson_ci(54, 20)
    assert rate.value == 54 / 20
    assert st.poisson.sf(53, rate.low * 20) == pytest.approx(0.025)
    assert st.poisson.cdf(54, rate.high * 20) == pytest.approx(0.025)
    x = np.random.default_rng(5).normal(10, 3, size=25)
    sd = sd_ci(x)
    assert sd.value == pytest.approx(np.std(x, ddof=1))
    assert (24 * sd.value**2 / sd.low**2) == pytest.approx(st.chi2.ppf(0.975, 24))
    assert (24 * sd.value**2 / sd.high**2) == pytest.approx(st.chi2.ppf(0.025, 24))
