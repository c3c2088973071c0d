"""Statistics of the report: means with 95 % confidence intervals, paired comparisons of two methods
trial by trial, and Holm's correction.

The sweeps are paired (``design.py``): at one trial index every method meets the same site and the
same human draws, so two methods are compared through the per-trial differences
``d_i = a_i - b_i`` (in the report: ARROCH minus a baseline; negative means ARROCH is lower).

Conventions (so a reader can recompute any number from the CSV):

- **differences** are rounded to 1e-6 (the CSV holds times to the millisecond), so that differences
  equal in the CSV are equal here and tie in the ranks;
- **mean with confidence interval**: Student's t interval, ``mean ± t(0.975, n-1) · sd / sqrt(n)``,
  ``sd`` with ``n - 1``; none for fewer than two values. The same for the mean difference; when the
  differences have no spread the interval is the point itself;
- **fewer than two pairs**: no test (every statistic NaN, shown as n/a);
- **paired t-test**: ``t = mean(d) / (sd(d) / sqrt(n))`` with ``n - 1`` degrees of freedom, two-sided
  (``scipy.stats.ttest_rel``); undefined (NaN) when the differences have no spread;
- **Wilcoxon signed-rank**, two-sided: zero differences are dropped (Wilcoxon's original
  treatment, ``zero_method="wilcox"``: a pair in which both methods gave the same value says
  nothing about which one is lower); the nonzero ``|d|`` are ranked with mid-ranks for ties;
  ``W = min(R+, R-)`` (scipy's two-sided statistic). The p-value comes from the exact null
  distribution when no two ``|d|`` tie and there are at most 50 nonzero differences; with ties and
  at most 16 nonzero differences, from the exact enumeration of the ``2^k`` sign flips of the
  mid-ranks; otherwise from the normal approximation with the tie correction and no continuity
  correction. With no nonzero difference ``W = 0`` and ``p = 1`` (every sign flip gives the same);
- **effect size** ``d_z = mean(d) / sd(d)``; NaN (not 0 or infinity) when the differences have no
  spread;
- **equivalence (TOST)** against a margin ``δ``: two one-sided paired t-tests,
  ``p1 = P(T > (mean(d) + δ) / se)`` (H0: mean <= -δ) and ``p2 = P(T < (mean(d) - δ) / se)``
  (H0: mean >= δ), ``T`` Student's t with ``n - 1`` degrees of freedom, ``se = sd(d) / sqrt(n)``;
  ``p = max(p1, p2)``. With no spread (``se = 0``) the statistics are infinite: ``p = 0`` when
  ``|mean(d)| < δ`` and ``p = 1`` otherwise;
- **sign-flip permutation test** (for counts, whose differences are small integers with many ties
  and zeros): under H0 each difference is as likely to have either sign; statistic ``S = sum(d)``;
  two-sided ``p`` = twice the smaller one-sided p (``scipy.stats.permutation_test`` with
  ``permutation_type="samples"`` on the nonzero differences; for this symmetric null it equals
  ``P(|S*| >= |S|)``). Zeros are dropped (flipping a zero changes nothing). Exact enumeration of the
  ``2^k`` sign flips when ``k``, the number of nonzero differences, is at most 16; otherwise
  ``PERMUTATION_RESAMPLES`` random flips drawn with the fixed seed ``PERMUTATION_SEED`` (so the
  report is byte-reproducible), one-sided p's counted as ``(1 + hits) / (1 + resamples)``. With no
  nonzero difference ``p = 1``;
- **Holm–Bonferroni**: adjusted ``p_(i) = max_{j <= i} min(1, (m - j + 1) p_(j))`` over the sorted
  p-values of one family; NaN is not a test and stays NaN;
- **the interval of the deciding test, at its Holm level** (:func:`holm_alphas`): Holm tests the
  j-th smallest p-value at ``α / (m - j + 1)`` and stops at the first it cannot reject; each test's
  interval is computed at the level Holm tested it at (``1 - α / (m - j + 1)``), and every test from
  the stopping step on at the stopping step's level. An interval then excludes 0 exactly when Holm
  rejects (up to the discreteness of the test): the table's interval and its verdict agree;
- **Hodges–Lehmann estimate with its Wilcoxon interval** (times, :func:`hodges_lehmann`): the median
  of the ``N = n(n+1)/2`` Walsh averages ``(d_i + d_j) / 2, i <= j`` (all differences, zeros
  included), and the interval ``[A_(c+1), A_(N-c)]`` of the sorted Walsh averages, ``c`` the largest
  count with ``P(T+ <= c) <= α/2`` under the exact null distribution of the signed-rank statistic
  (exact for distinct nonzero differences; with ties or zeros its coverage is approximate).
  Unbounded when even ``c = 0`` is too likely (few pairs at a strict level);
- **the sign-flip interval** (counts, :func:`sign_flip_interval`): the mean difference and the
  shifts ``δ`` the sign-flip test of ``d - δ`` does not reject at the level (test inversion: the
  same ``2^n`` flips when ``n <= 16``, else ``FLIP_INTERVAL_RESAMPLES`` flips with the fixed seed),
  its ends found by bisection to ``1e-4``; unbounded on a side where even the most extreme shift in
  the data is not rejected.

scipy is imported on first use, so commands that never make a report do not pay for it.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

NAN = float("nan")
EXACT_WILCOXON_MAX = 50  # nonzero differences, no ties: exact null distribution up to here
EXACT_FLIPS_MAX = 16  # nonzero differences whose 2^k sign flips are enumerated exactly (65 536)
PERMUTATION_RESAMPLES = 99_999  # random sign flips beyond that
PERMUTATION_SEED = 20_240  # fixed: the same CSV gives the same p-values, byte for byte
DIFF_DECIMALS = 6  # differences rounded here (the CSV has milliseconds) so equal differences tie
FLIP_INTERVAL_RESAMPLES = 20_000  # random sign flips for the interval beyond EXACT_FLIPS_MAX differences
INF = float("inf")


def _scipy_stats():  # noqa: ANN202 - the module
    from scipy import stats

    return stats


# ---------------------------------------------------------------------------- one sample


@dataclass(frozen=True)
class Summary:
    n: int
    mean: float
    sd: float
    ci_low: float
    ci_high: float

    @property
    def half_width(self) -> float:
        return (self.ci_high - self.ci_low) / 2.0


def summarize(values: Sequence[float]) -> Summary:
    """Mean, sample sd and the 95 % t interval of ``values`` (NaN where undefined)."""
    x = np.asarray(values, dtype=float)
    n = int(x.size)
    if n == 0:
        return Summary(0, NAN, NAN, NAN, NAN)
    mean = float(x.mean())
    if n == 1:
        return Summary(1, mean, NAN, NAN, NAN)
    sd = float(x.std(ddof=1))
    half = float(_scipy_stats().t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
    return Summary(n, mean, sd, mean - half, mean + half)


# ---------------------------------------------------------------------------- paired tests


def differences(a: Sequence[float], b: Sequence[float]) -> np.ndarray:
    """``a_i - b_i``, rounded so that equal differences in the CSV are equal here."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.shape != y.shape:
        raise ValueError(f"paired samples must have the same length (got {x.size} and {y.size})")
    return np.round(x - y, DIFF_DECIMALS)


def paired_t(d: np.ndarray) -> tuple[float, float]:
    """(t, two-sided p) of the paired t-test on the differences; NaN without spread or pairs."""
    if d.size < 2 or float(d.std(ddof=1)) == 0.0:
        return NAN, NAN
    res = _scipy_stats().ttest_1samp(d, 0.0)  # the same as ttest_rel on the two samples
    return float(res.statistic), float(res.pvalue)


@dataclass(frozen=True)
class SignedRank:
    w: float  # min(R+, R-)
    r_plus: float  # sum of the ranks of the positive differences
    r_minus: float
    p: float
    method: str  # exact, exact flips, normal, none


def wilcoxon_signed_rank(d: np.ndarray) -> SignedRank:
    """The two-sided Wilcoxon signed-rank test of the differences (module docstring)."""
    nonzero = d[d != 0]
    k = int(nonzero.size)
    if d.size < 2:
        return SignedRank(NAN, NAN, NAN, NAN, "none")
    if k == 0:
        return SignedRank(0.0, 0.0, 0.0, 1.0, "none")
    st = _scipy_stats()
    ranks = st.rankdata(np.abs(nonzero))
    r_plus, r_minus = float(ranks[nonzero > 0].sum()), float(ranks[nonzero < 0].sum())
    ties = np.unique(np.abs(nonzero)).size < k
    if not ties and k <= EXACT_WILCOXON_MAX:
        method, how = "exact", "exact"
    elif k <= EXACT_FLIPS_MAX:
        method, how = st.PermutationMethod(n_resamples=2**EXACT_FLIPS_MAX), "exact flips"
    else:
        method, how = "asymptotic", "normal"
    res = st.wilcoxon(nonzero, zero_method="wilcox", correction=False, alternative="two-sided", method=method)
    return SignedRank(float(res.statistic), r_plus, r_minus, min(1.0, float(res.pvalue)), how)


def _sum(x: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.sum(x, axis=axis)


def sign_flip_test(d: np.ndarray) -> float:
    """Two-sided p of the sign-flip permutation test of ``sum(d)`` (module docstring)."""
    if d.size < 2:
        return NAN
    nonzero = d[d != 0]
    k = int(nonzero.size)
    if k <= 1:
        return 1.0  # no difference, or one: its two sign arrangements have the same |sum|
    exact = k <= EXACT_FLIPS_MAX
    res = _scipy_stats().permutation_test(
        (nonzero,),
        _sum,
        permutation_type="samples",
        vectorized=True,
        alternative="two-sided",
        n_resamples=2**k if exact else PERMUTATION_RESAMPLES,
        rng=np.random.default_rng(PERMUTATION_SEED),
    )
    return min(1.0, float(res.pvalue))


def tost(d: np.ndarray, margin: float) -> float:
    """p of the paired equivalence test (two one-sided t-tests) within ``±margin``."""
    if d.size < 2 or not margin > 0:
        return NAN
    n = d.size
    mean, se = float(d.mean()), float(d.std(ddof=1)) / math.sqrt(n)
    if se == 0.0:
        return 0.0 if abs(mean) < margin else 1.0
    t_dist = _scipy_stats().t
    p_above_lower = float(t_dist.sf((mean + margin) / se, n - 1))  # H0: mean <= -margin
    p_below_upper = float(t_dist.cdf((mean - margin) / se, n - 1))  # H0: mean >= +margin
    return max(p_above_lower, p_below_upper)


@dataclass(frozen=True)
class Paired:
    """Sample a (ARROCH) against sample b (a baseline), pair by pair: ``diff = a - b``."""

    n: int  # pairs
    n_nonzero: int  # pairs with a nonzero difference
    mean_a: float
    mean_b: float
    mean_diff: float
    sd_diff: float
    ci_low: float  # 95 % t interval of the mean difference
    ci_high: float
    t: float
    t_p: float
    wilcoxon: SignedRank
    perm_p: float  # NaN unless asked for (counts)
    d_z: float
    margin: float
    tost_p: float


def paired(a: Sequence[float], b: Sequence[float], *, margin: float, permutation: bool = False) -> Paired:
    """Every paired statistic of the module docstring; ``permutation``: run the sign-flip test too."""
    d = differences(a, b)
    n = int(d.size)
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    mean_a = float(x.mean()) if n else NAN
    mean_b = float(y.mean()) if n else NAN
    s = summarize(d)
    with warnings.catch_warnings():
        # Nearly constant differences make scipy warn about precision; the cases are handled above.
        warnings.simplefilter("ignore", RuntimeWarning)
        t, t_p = paired_t(d)
        rank = wilcoxon_signed_rank(d)
        perm_p = sign_flip_test(d) if permutation else NAN
    ci_low, ci_high = s.ci_low, s.ci_high
    if n >= 2 and s.sd == 0.0:
        ci_low = ci_high = s.mean
    d_z = s.mean / s.sd if n >= 2 and s.sd > 0 else NAN
    return Paired(
        n,
        int(np.count_nonzero(d)),
        mean_a,
        mean_b,
        s.mean,
        s.sd,
        ci_low,
        ci_high,
        t,
        t_p,
        rank,
        perm_p,
        d_z,
        margin,
        tost(d, margin),
    )


# ---------------------------------------------------------------------------- families


def holm(pvalues: Sequence[float]) -> list[float]:
    """Holm–Bonferroni adjusted p-values (NaN stays NaN and does not count as a test)."""
    indexed = [(p, i) for i, p in enumerate(pvalues) if not math.isnan(p)]
    indexed.sort()
    m = len(indexed)
    adjusted = [NAN] * len(pvalues)
    running = 0.0
    for rank, (p, i) in enumerate(indexed):
        running = max(running, min(1.0, (m - rank) * p))
        adjusted[i] = running
    return adjusted


def holm_alphas(pvalues: Sequence[float], alpha: float) -> list[float]:
    """The significance level Holm tests each p-value at (module docstring); NaN for NaN."""
    indexed = sorted((p, i) for i, p in enumerate(pvalues) if not math.isnan(p))
    m = len(indexed)
    levels = [NAN] * len(pvalues)
    stopped: float | None = None
    for rank, (p, i) in enumerate(indexed):
        level = alpha / (m - rank)
        if stopped is None and p > level:
            stopped = level
        levels[i] = level if stopped is None else stopped
    return levels


# ---------------------------------------------------------------------------- intervals


@dataclass(frozen=True)
class Interval:
    """An estimate with the confidence interval of the test that decides the verdict."""

    estimate: float
    low: float
    high: float
    level: float  # confidence level, 1 - the alpha it was computed at
    kind: str  # what estimate and interval these are (module docstring)


def _signed_rank_cdf(n: int) -> np.ndarray:
    """P(T+ <= t) for t = 0..n(n+1)/2 under H0 (distinct nonzero differences)."""
    dist = np.zeros(n * (n + 1) // 2 + 1)
    dist[0] = 1.0
    for k in range(1, n + 1):  # each rank k is in T+ with probability 1/2
        shifted = np.zeros_like(dist)
        shifted[k:] = dist[: dist.size - k]
        dist = 0.5 * (dist + shifted)
    return np.cumsum(dist)


def hodges_lehmann(d: np.ndarray, alpha: float) -> Interval:
    """The Hodges–Lehmann estimate of the differences and its Wilcoxon interval at ``1 - alpha``."""
    kind = "Hodges–Lehmann, Wilcoxon interval"
    n = int(d.size)
    if n < 2 or math.isnan(alpha):
        return Interval(NAN, NAN, NAN, NAN, kind)
    i, j = np.triu_indices(n)
    walsh = np.sort((d[i] + d[j]) / 2.0)
    estimate = float(np.median(walsh))
    cdf = _signed_rank_cdf(n)
    below = np.nonzero(cdf <= alpha / 2.0 + 1e-12)[0]
    if below.size == 0:
        return Interval(estimate, -INF, INF, 1.0 - alpha, kind)
    c = int(below[-1])
    return Interval(estimate, float(walsh[c]), float(walsh[walsh.size - 1 - c]), 1.0 - alpha, kind)


def _flips(n: int) -> np.ndarray:
    """The sign-flip matrix of the interval: every pattern when n <= EXACT_FLIPS_MAX, else seeded draws."""
    if n <= EXACT_FLIPS_MAX:
        patterns = (np.arange(2**n)[:, None] >> np.arange(n)) & 1
        return (1 - 2 * patterns).astype(float)
    rng = np.random.default_rng(PERMUTATION_SEED)
    return rng.choice((-1.0, 1.0), size=(FLIP_INTERVAL_RESAMPLES, n))


def sign_flip_interval(d: np.ndarray, alpha: float, tolerance: float = 1e-4) -> Interval:
    """The mean difference and the shifts the sign-flip test does not reject at ``alpha`` (docstring)."""
    kind = "mean, sign-flip interval"
    n = int(d.size)
    if n < 2 or math.isnan(alpha):
        return Interval(NAN, NAN, NAN, NAN, kind)
    flips = _flips(n)
    mean = float(d.mean())

    def p(delta: float) -> float:
        x = d - delta
        observed = abs(float(x.sum()))
        return float(np.mean(np.abs(flips @ x) >= observed - 1e-9))

    def end(outer: float) -> float:
        """The last shift toward ``outer`` that is not rejected (bisection); ±inf if ``outer`` is not."""
        if p(outer) > alpha:
            return -INF if outer < mean else INF
        inner = mean
        while abs(outer - inner) > tolerance:
            middle = (inner + outer) / 2.0
            inner, outer = (middle, outer) if p(middle) > alpha else (inner, middle)
        return inner

    spread = float(d.max() - d.min()) or 1.0
    return Interval(mean, end(float(d.min()) - spread), end(float(d.max()) + spread), 1.0 - alpha, kind)
