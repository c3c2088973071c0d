"""The statistics of a study: paired tests across conditions, and the intervals the calibration states.

Paired comparison of condition A against condition B over the participants who have both values,
``d_i = a_i - b_i``:

- **Wilcoxon signed-rank**, two-sided. Zero differences are dropped (Wilcoxon's treatment: a
  participant who scored both conditions the same says nothing about which is higher); the nonzero
  ``|d|`` are ranked with mid-ranks for ties. ``R+`` and ``R-`` are the rank sums of the positive
  and negative differences, the statistic ``W = min(R+, R-)``. The p-value is exact: the null
  distribution of ``R+`` given the observed mid-ranks (every sign equally likely) is computed by
  convolution over the doubled ranks (integers), and ``p = P(|R+* - E| >= |R+ - E|)``. Without ties
  this is the classical exact test (equal to scipy's ``method="exact"``); with ties (Likert items are
  full of them) it is the exact conditional test. Above ``EXACT_MAX`` nonzero differences the normal
  approximation with the tie correction is used instead (and named).
- **median difference** and the **Hodges-Lehmann** estimate (the median of the Walsh averages
  ``(d_i + d_j) / 2``, ``i <= j``, zeros included): the shift the signed-rank test is about.
- **paired t** (``scipy.stats.ttest_rel``), reported beside it; NaN when the differences have no spread.
- **Holm-Bonferroni** within a family of tests: adjusted ``p_(i) = max_{j<=i} min(1, (m-j+1) p_(j))``;
  NaN (no test) stays NaN and does not count.

Intervals (95 % unless told): Student's t for a mean, chi-square for a standard deviation,
Clopper-Pearson for a proportion, Garwood's exact interval for a Poisson count.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
from scipy import stats as st

NAN = float("nan")
EXACT_MAX = 400  # nonzero differences up to which the signed-rank p is exact (convolution of ~n^2 terms)
ALPHA = 0.05


# ---------------------------------------------------------------------------- paired tests


@dataclass(frozen=True)
class SignedRank:
    n_nonzero: int
    w: float  # min(R+, R-)
    r_plus: float
    r_minus: float
    p: float
    method: str  # exact, normal, none


def signed_rank(d: Sequence[float]) -> SignedRank:
    """Two-sided Wilcoxon signed-rank test of the differences ``d`` (module docstring)."""
    x = np.asarray(d, dtype=float)
    nonzero = x[x != 0]
    k = int(nonzero.size)
    if x.size < 2:
        return SignedRank(k, NAN, NAN, NAN, NAN, "none")
    if k == 0:
        return SignedRank(0, 0.0, 0.0, 0.0, 1.0, "none")
    ranks = st.rankdata(np.abs(nonzero))  # mid-ranks: multiples of 0.5
    r_plus, r_minus = float(ranks[nonzero > 0].sum()), float(ranks[nonzero < 0].sum())
    doubled = np.rint(2 * ranks).astype(np.int64)
    total = int(doubled.sum())
    observed = int(round(2 * r_plus))
    if k <= EXACT_MAX:
        # P(2R+ = s) under H0: each rank's sign a fair coin, independently.
        dist = np.zeros(total + 1)
        dist[0] = 1.0
        for r in doubled:
            shifted = np.zeros_like(dist)
            shifted[r:] = dist[: dist.size - r]
            dist = 0.5 * (dist + shifted)
        s = np.arange(total + 1)
        # |2s - total| >= |2 obs - total|, all in integers: no rounding decides a tie.
        p = float(dist[np.abs(2 * s - total) >= abs(2 * observed - total)].sum())
        method = "exact"
    else:
        mean = total / 4.0  # E[R+] = sum of the ranks / 2 (total is twice that sum)
        var = float((ranks**2).sum()) / 4.0  # Var[R+] given the mid-ranks: each rank in or out with 1/2
        z = (r_plus - mean) / math.sqrt(var)
        p = float(2 * st.norm.sf(abs(z)))
        method = "normal"
    return SignedRank(k, min(r_plus, r_minus), r_plus, r_minus, min(1.0, p), method)


def hodges_lehmann(d: Sequence[float]) -> float:
    """The median of the Walsh averages ``(d_i + d_j) / 2`` over ``i <= j``."""
    x = np.asarray(d, dtype=float)
    if x.size == 0:
        return NAN
    i, j = np.triu_indices(x.size)
    return float(np.median((x[i] + x[j]) / 2.0))


def paired_t(a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    """(t, two-sided p) of the paired t-test; NaN with fewer than two pairs or no spread in the differences."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.size < 2 or float(np.std(x - y)) == 0.0:
        return NAN, NAN
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # near-constant differences: scipy warns on precision
        res = st.ttest_rel(x, y)
    return float(res.statistic), float(res.pvalue)


@dataclass(frozen=True)
class PairedResult:
    """Condition ``a`` against condition ``b`` on one measure, ``d = a - b``."""

    measure: str
    family: str
    a: str
    b: str
    n: int  # pairs
    mean_a: float
    mean_b: float
    median_diff: float
    hodges_lehmann: float
    wilcoxon: SignedRank
    t: float
    t_p: float
    p_holm: float = NAN
    decision: str = ""

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["wilcoxon"] = asdict(self.wilcoxon)
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in out.items()}


def paired(measure: str, family: str, a_name: str, b_name: str, a: Sequence[float], b: Sequence[float]) -> PairedResult:
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.shape != y.shape:
        raise ValueError(f"{measure}: paired samples differ in length ({x.size} and {y.size})")
    d = x - y
    n = int(d.size)
    t, t_p = paired_t(x, y)
    return PairedResult(
        measure=measure,
        family=family,
        a=a_name,
        b=b_name,
        n=n,
        mean_a=float(x.mean()) if n else NAN,
        mean_b=float(y.mean()) if n else NAN,
        median_diff=float(np.median(d)) if n else NAN,
        hodges_lehmann=hodges_lehmann(d),
        wilcoxon=signed_rank(d),
        t=t,
        t_p=t_p,
    )


def holm(pvalues: Sequence[float]) -> list[float]:
    """Holm-Bonferroni adjusted p-values of one family (NaN: no test, left out of the count)."""
    tested = sorted((p, i) for i, p in enumerate(pvalues) if not math.isnan(p))
    m = len(tested)
    out = [NAN] * len(pvalues)
    running = 0.0
    for rank, (p, i) in enumerate(tested):
        running = max(running, min(1.0, (m - rank) * p))
        out[i] = running
    return out


def decide(result: PairedResult, p_holm: float, alpha: float = ALPHA) -> str:
    """The words for one test: the direction only when the Holm-adjusted p is below ``alpha``."""
    if result.n < 2 or math.isnan(p_holm):
        return f"not tested (fewer than 2 pairs with a value in both {result.a} and {result.b})"
    if p_holm >= alpha:
        return "no difference detected"
    direction = "higher" if result.wilcoxon.r_plus > result.wilcoxon.r_minus else "lower"
    return f"{direction} in {result.a} than in {result.b} at α={alpha:g} after Holm"


def correct_family(results: list[PairedResult]) -> list[PairedResult]:
    """The family's results with Holm-adjusted p-values and decisions filled in."""
    adjusted = holm([r.wilcoxon.p for r in results])
    return [replace(r, p_holm=p, decision=decide(r, p)) for r, p in zip(results, adjusted, strict=True)]


# ---------------------------------------------------------------------------- intervals


@dataclass(frozen=True)
class Estimate:
    value: float
    low: float
    high: float
    n: int


def mean_ci(values: Sequence[float], level: float = 0.95) -> Estimate:
    """Mean and its Student t interval (NaN bounds with fewer than two values)."""
    x = np.asarray(values, dtype=float)
    n = int(x.size)
    if n == 0:
        return Estimate(NAN, NAN, NAN, 0)
    mean = float(x.mean())
    if n == 1:
        return Estimate(mean, NAN, NAN, 1)
    half = float(st.t.ppf(0.5 + level / 2, n - 1)) * float(x.std(ddof=1)) / math.sqrt(n)
    return Estimate(mean, mean - half, mean + half, n)


def sd_ci(values: Sequence[float], level: float = 0.95) -> Estimate:
    """Sample standard deviation (n - 1) and its chi-square interval (normal data)."""
    x = np.asarray(values, dtype=float)
    n = int(x.size)
    if n < 2:
        return Estimate(NAN, NAN, NAN, n)
    sd = float(x.std(ddof=1))
    lo = sd * math.sqrt((n - 1) / float(st.chi2.ppf(0.5 + level / 2, n - 1)))
    hi = sd * math.sqrt((n - 1) / float(st.chi2.ppf(0.5 - level / 2, n - 1)))
    return Estimate(sd, lo, hi, n)


def clopper_pearson(successes: int, trials: int, level: float = 0.95) -> Estimate:
    """The proportion and its exact (Clopper-Pearson) interval."""
    if trials <= 0:
        return Estimate(NAN, NAN, NAN, 0)
    a = 1 - level
    lo = 0.0 if successes == 0 else float(st.beta.ppf(a / 2, successes, trials - successes + 1))
    hi = 1.0 if successes == trials else float(st.beta.ppf(1 - a / 2, successes + 1, trials - successes))
    return Estimate(successes / trials, lo, hi, trials)


def poisson_ci(count: int, exposure: float, level: float = 0.95) -> Estimate:
    """A Poisson rate ``count / exposure`` and Garwood's exact interval."""
    if exposure <= 0:
        return Estimate(NAN, NAN, NAN, 0)
    a = 1 - level
    lo = 0.0 if count == 0 else float(st.chi2.ppf(a / 2, 2 * count)) / 2
    hi = float(st.chi2.ppf(1 - a / 2, 2 * count + 2)) / 2
    return Estimate(count / exposure, lo / exposure, hi / exposure, count)


def quartiles(values: Sequence[float]) -> tuple[float, float, float]:
    """(first quartile, median, third quartile), numpy's linear interpolation; NaN when empty."""
    if len(values) == 0:
        return NAN, NAN, NAN
    q1, q2, q3 = np.percentile(np.asarray(values, dtype=float), [25, 50, 75])
    return float(q1), float(q2), float(q3)
