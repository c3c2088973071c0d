"""The paired statistics against values computed by hand or by brute-force enumeration."""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np
import pytest

from services.experiments.stats import differences, holm, paired, sign_flip_test, tost, wilcoxon_signed_rank
from tests.experiments.helpers import T_975, t_two_sided, t_upper_tail

# ARROCH and a baseline over five paired trials. By hand:
#   d = a - b = -20 -15 0 -30 -10: mean -15, deviations -5 0 15 -15 5, squares 25+0+225+225+25 = 500,
#   variance 500/4 = 125, se = sqrt(125/5) = 5, t = -15/5 = -3 with 4 degrees of freedom.
A = [600.0, 610.0, 620.0, 630.0, 640.0]
B = [620.0, 625.0, 620.0, 660.0, 650.0]


def test_paired_times_by_hand() -> None:
    r = paired(A, B, margin=30.0)
    assert (r.n, r.n_nonzero) == (5, 4)
    assert (r.mean_a, r.mean_b, r.mean_diff) == pytest.approx((620.0, 635.0, -15.0))
    assert r.sd_diff == pytest.approx(math.sqrt(125))
    assert (r.ci_low, r.ci_high) == pytest.approx((-15 - T_975[4] * 5, -15 + T_975[4] * 5))
    assert r.t == pytest.approx(-3.0)
    assert r.t_p == pytest.approx(t_two_sided(-3.0, 4), abs=1e-7)
    assert r.d_z == pytest.approx(-15 / math.sqrt(125))
    # Wilcoxon: the zero is dropped; |d| = 20 15 30 10 rank 3 2 4 1, all negative: R+ = 0, R- = 10.
    # Exact: only 1 of the 2^4 sign patterns has R+ <= 0, two-sided 2/16.
    assert (r.wilcoxon.w, r.wilcoxon.r_plus, r.wilcoxon.r_minus) == (0.0, 0.0, 10.0)
    assert r.wilcoxon.p == pytest.approx(2 / 16)
    # TOST ±30: t1 = (-15 + 30) / 5 = 3 (p1 = P(T > 3)), t2 = (-15 - 30) / 5 = -9 (p2 = P(T < -9)); p = max.
    assert r.tost_p == pytest.approx(max(t_upper_tail(3.0, 4), t_upper_tail(9.0, 4)), abs=1e-7)
    # ±10: t1 = (-15 + 10) / 5 = -1, p1 = P(T > -1) = 1 - P(T > 1): far from equivalent.
    assert tost(differences(A, B), 10.0) == pytest.approx(1 - t_upper_tail(1.0, 4), abs=1e-7)
    assert math.isnan(r.perm_p)  # asked for counts only


def test_wilcoxon_exact_and_zeros_dropped() -> None:
    # |d| 1 2 3 4 5 rank 1..5, only 5 positive: R+ = 5, R- = 10, W = 5. Subsets of {1..5} summing to <= 5:
    # {}, {1}..{5}, {1,2}, {1,3}, {1,4}, {2,3}: 10 of 32; two-sided 20/32.
    d = np.array([-1.0, -2.0, -3.0, -4.0, 5.0])
    r = wilcoxon_signed_rank(d)
    assert (r.w, r.p, r.method) == (5.0, pytest.approx(20 / 32), "exact")
    with_zeros = wilcoxon_signed_rank(np.concatenate([d, [0.0, 0.0]]))
    assert (with_zeros.w, with_zeros.p) == (r.w, r.p)


def test_wilcoxon_ties_small_sample_enumerates_the_sign_flips() -> None:
    d = np.array([-1.0, -1.0, -2.0, 3.0])
    ranks = [1.5, 1.5, 3.0, 4.0]  # mid-ranks of |d|
    observed = 4.0  # R+: only the 3 is positive
    flips = [
        sum(r for r, s in zip(ranks, signs, strict=True) if s > 0) for signs in itertools.product((-1, 1), repeat=4)
    ]
    mean = sum(ranks) / 2
    p = sum(abs(f - mean) >= abs(observed - mean) for f in flips) / len(flips)  # 12/16
    r = wilcoxon_signed_rank(d)
    assert (r.r_plus, r.method) == (observed, "exact flips")
    assert r.p == pytest.approx(p) == pytest.approx(0.75)


def test_wilcoxon_exact_for_twenty_without_ties() -> None:
    # d = -1..-20 with 3, 7, 12 positive: R+ = 22. Subsets of {1..20} summing to <= 22, counted by DP.
    d = np.array([float(i) if i in (3, 7, 12) else -float(i) for i in range(1, 21)])
    counts = [1] + [0] * 210
    for i in range(1, 21):
        counts = [c + (counts[s - i] if s >= i else 0) for s, c in enumerate(counts)]
    r = wilcoxon_signed_rank(d)
    assert (r.w, r.method) == (22.0, "exact")
    assert r.p == pytest.approx(2 * sum(counts[:23]) / 2**20, rel=1e-9)


def test_wilcoxon_normal_approximation_with_ties() -> None:
    # 20 nonzero differences with ties: |1| x8 (ranks 1-8, mid 4.5), |2| x6 (9-14, mid 11.5), |3| x6 (15-20, mid 17.5);
    # positive: four of the 3s. R+ = 70, R- = 140. Mean 105; variance 20*21*41/24 - (504 + 210 + 210)/48 = 698.25.
    d = np.array([-1.0] * 8 + [-2.0] * 6 + [3.0] * 4 + [-3.0] * 2)
    z = (70 - 105) / math.sqrt(698.25)
    r = wilcoxon_signed_rank(d)
    assert (r.w, r.r_plus, r.r_minus, r.method) == (70.0, 70.0, 140.0, "normal")
    assert r.p == pytest.approx(math.erfc(abs(z) / math.sqrt(2)), rel=1e-9)


def test_sign_flip_exact_by_hand() -> None:
    # Nonzero d = -1 -2 -1: the 8 sign patterns give sums 4 2 0 2 -2 0 -2 -4; |S| >= 4 in 2 of them.
    d = np.array([-1.0, -2.0, -1.0, 0.0])
    assert sign_flip_test(d) == pytest.approx(2 / 8)
    r = paired([1, 0, 2, 3], [2, 2, 3, 3], margin=0.5, permutation=True)  # the same differences
    assert r.perm_p == pytest.approx(0.25)


def test_sign_flip_with_a_single_nonzero_difference_is_p_1() -> None:
    # One nonzero difference: +3 and -3 are the only arrangements, |S| = 3 in both.
    assert sign_flip_test(np.array([0.0, 3.0, 0.0])) == 1.0
    assert wilcoxon_signed_rank(np.array([0.0, 3.0, 0.0])).p == pytest.approx(1.0)


def test_sign_flip_monte_carlo_is_reproducible_and_close_to_exact() -> None:
    d = np.array([-1.0] * 14 + [1.0] * 3 + [-2.0] * 3)  # 20 nonzero: beyond exact enumeration
    observed = abs(d.sum())
    # Exact distribution of sum(±|d_i|), by convolution.
    dist = {0.0: 1}
    for x in np.abs(d):
        nxt: dict[float, int] = {}
        for s, c in dist.items():
            for v in (s + x, s - x):
                nxt[v] = nxt.get(v, 0) + c
        dist = nxt
    exact = sum(c for s, c in dist.items() if abs(s) >= observed - 1e-9) / 2**20
    first, second = sign_flip_test(d), sign_flip_test(d.copy())
    assert first == second  # a fixed seed: byte-reproducible
    assert first == pytest.approx(exact, abs=0.005)


def test_zero_variance_is_not_available_and_does_not_warn() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        same = paired([5, 6, 7, 8], [5, 6, 7, 8], margin=0.5, permutation=True)
        shifted = paired([5, 5, 5], [4, 4, 4], margin=0.5, permutation=True)
    # Identical pairs: no difference at all. Tests of a difference say nothing (p = 1), t and d_z are undefined,
    # and the equivalence test is decided (se = 0, |mean| < margin: p = 0).
    assert math.isnan(same.t) and math.isnan(same.t_p) and math.isnan(same.d_z)
    assert (same.wilcoxon.p, same.perm_p, same.tost_p) == (1.0, 1.0, 0.0)
    assert (same.ci_low, same.ci_high) == (0.0, 0.0)
    # Always one more: t and d_z undefined; the rank and flip tests still work (2 of 8 patterns as extreme);
    # 1 is outside ±0.5, so not equivalent.
    assert math.isnan(shifted.t) and math.isnan(shifted.d_z)
    assert shifted.wilcoxon.p == pytest.approx(0.25) and shifted.perm_p == pytest.approx(0.25)
    assert shifted.tost_p == 1.0
    assert (shifted.ci_low, shifted.ci_high) == (1.0, 1.0)


def test_tost_on_near_identical_pairs() -> None:
    # d = 0.1 -0.1 0.2 -0.2 0: mean 0, variance 0.1/4 = 0.025, se = sqrt(0.005); t1 = 30/se: equivalent beyond doubt.
    b = [600.0, 610.0, 620.0, 630.0, 640.0]
    a = [v + e for v, e in zip(b, (0.1, -0.1, 0.2, -0.2, 0.0), strict=True)]
    r = paired(a, b, margin=30.0)
    assert r.mean_diff == pytest.approx(0.0, abs=1e-12)
    assert r.tost_p < 1e-9
    # With a margin the size of the noise it is not: t1 = 0.05 / sqrt(0.005) = 0.7071.
    assert r.tost_p < tost(differences(a, b), 0.05) == pytest.approx(t_upper_tail(0.05 / math.sqrt(0.005), 4), abs=1e-7)


def test_fewer_than_two_pairs_is_no_test() -> None:
    r = paired([600.0], [650.0], margin=30.0, permutation=True)
    assert r.n == 1 and r.mean_diff == -50.0
    assert all(math.isnan(v) for v in (r.sd_diff, r.ci_low, r.t, r.t_p, r.wilcoxon.p, r.perm_p, r.d_z, r.tost_p))
    with pytest.raises(ValueError, match="same length"):
        paired([1.0, 2.0], [1.0], margin=1.0)


def test_holm_by_hand() -> None:
    # Sorted 0.01, 0.03, 0.04 → 3·0.01, max(0.03, 2·0.03), max(0.06, 1·0.04); NaN is not a test.
    adjusted = holm([0.01, 0.04, 0.03, float("nan")])
    assert adjusted[:3] == pytest.approx([0.03, 0.06, 0.06])
    assert math.isnan(adjusted[3])


# ---------------------------------------------------------------------------- the deciding test's interval


def test_hodges_lehmann_and_its_wilcoxon_interval_by_hand() -> None:
    from services.experiments.stats import hodges_lehmann

    d = np.array([-5.0, -3.0, -8.0, -1.0, -12.0, -7.0, 2.0, -4.0, -6.0, -9.0])
    walsh = sorted((d[i] + d[j]) / 2 for i in range(10) for j in range(i, 10))  # 55 Walsh averages
    # Exact signed-rank null for n = 10: P(T+ <= 8) = 25/1024 <= 0.025 < P(T+ <= 9) = 33/1024, so c = 8 and the
    # interval is the 9th smallest and the 9th largest Walsh average (R's wilcox.test(conf.int = TRUE) gives the same).
    counts = [
        sum(
            1
            for signs in itertools.product((0, 1), repeat=10)
            if sum(k * s for k, s in zip(range(1, 11), signs, strict=True)) <= t
        )
        for t in (8, 9)
    ]
    assert counts == [25, 33]
    i = hodges_lehmann(d, 0.05)
    assert i.estimate == pytest.approx(float(np.median(walsh)))
    assert (i.low, i.high, i.level) == pytest.approx((walsh[8], walsh[-9], 0.95))
    # Too few pairs for the level: unbounded, not a made-up interval.
    few = hodges_lehmann(np.array([-3.0, -1.0, -2.0]), 0.05)
    assert (few.low, few.high) == (-math.inf, math.inf)


def test_sign_flip_interval_is_the_set_of_shifts_the_test_keeps() -> None:
    from services.experiments.stats import sign_flip_interval

    d = np.array([-2.0, -1.0, -2.0, 0.0, -1.0, -3.0, -2.0, -1.0, 0.0, -2.0])
    i = sign_flip_interval(d, 0.05)
    assert i.estimate == pytest.approx(-1.4) and i.low < -1.4 < i.high < 0.0

    def p(delta: float) -> float:  # brute force: every sign pattern of d - delta
        x = d - delta
        flips = [
            abs(sum(s * v for s, v in zip(signs, x, strict=True))) for signs in itertools.product((-1, 1), repeat=10)
        ]
        return sum(f >= abs(x.sum()) - 1e-9 for f in flips) / len(flips)

    assert p(i.low + 0.01) > 0.05 and p(i.low - 0.01) <= 0.05
    assert p(i.high - 0.01) > 0.05 and p(i.high + 0.01) <= 0.05


def test_holm_levels_make_intervals_agree_with_the_verdicts() -> None:
    from services.experiments.stats import holm_alphas

    # Sorted: 0.01 is tested at 0.05/4 and rejected; 0.03 at 0.05/3 is not, so Holm stops: it and everything after
    # get that step's level.
    assert holm_alphas([0.01, 0.04, 0.03, math.nan, 0.2], 0.05) == pytest.approx(
        [0.0125, 0.05 / 3, 0.05 / 3, math.nan, 0.05 / 3], nan_ok=True
    )
    assert holm_alphas([0.001, 0.002], 0.05) == pytest.approx([0.025, 0.05])


def test_each_tests_interval_excludes_zero_exactly_when_holm_rejects(tmp_path) -> None:  # noqa: ANN001
    from services.experiments.comparisons import LOWER, TEAM_TIME, family
    from services.experiments.results import load_results
    from tests.experiments.helpers import row, write_trials

    rng = np.random.default_rng(3)
    rows = []
    for level, shift in ((2, -30.0), (3, -12.0), (4, -4.0), (5, 0.0)):
        for i in range(12):
            base = 600.0 + 10.0 * i
            noise = float(rng.normal(0.0, 15.0))
            rows += [
                row("arroch", level, i, team=base + shift + noise, doors=5),
                row("no-comm", level, i, team=base, doors=5),
            ]
    write_trials(tmp_path, rows)
    tests = family(load_results(tmp_path), TEAM_TIME)
    assert {t.outcome == LOWER for t in tests} == {True, False}  # both kinds present: the check below bites
    for t in tests:
        assert t.interval is not None and t.interval.kind == "Hodges–Lehmann, Wilcoxon interval"
        assert (t.interval.high < 0.0) == (t.outcome == LOWER), t.describe()
