"""Statistics of the report: means with 95 % confidence intervals, Welch's t-test, Mann–Whitney U,
Cohen's d, the rank-biserial correlation, and Holm's correction.

Conventions (so a reader can recompute any number from the CSV):

- confidence interval: Student's t interval, ``mean ± t(0.975, n-1) · sd / sqrt(n)``, ``sd`` with
  ``n - 1``; none for fewer than two values;
- Welch's t-test: two-sided, unequal variances (``scipy.stats.ttest_ind(equal_var=False)``);
- Mann–Whitney U: two-sided (``scipy.stats.mannwhitneyu``: exact for small samples without ties,
  otherwise the normal approximation with tie and continuity corrections); ``U`` is the first
  sample's: the pairs (a, b) with a > b, plus half the ties;
- Cohen's d: ``(mean_a - mean_b) / pooled sd``, pooled with ``n - 1`` weights;
- rank-biserial correlation: ``2 U / (n_a n_b) - 1`` = P(a > b) - P(a < b); negative when the first
  sample (ARROCH in the report) tends to be lower;
- when both samples have no spread the t-test is undefined and reported as not available (NaN),
  not as zero or one.

scipy is imported on first use, so commands that never make a report do not pay for it.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Sequence

import numpy as np

NAN = float("nan")


def _scipy_stats():  # noqa: ANN202 - the module
    from scipy import stats

    return stats


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


@dataclass(frozen=True)
class Comparison:
    """Sample a (ARROCH) against sample b (a baseline)."""

    n_a: int
    n_b: int
    mean_a: float
    mean_b: float
    welch_t: float
    welch_df: float
    welch_p: float
    mwu_u: float
    mwu_p: float
    cohen_d: float
    rank_biserial: float

    @property
    def diff(self) -> float:
        return self.mean_a - self.mean_b


def cohen_d(a: Sequence[float], b: Sequence[float]) -> float:
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.size < 2 or y.size < 2:
        return NAN
    pooled = math.sqrt(((x.size - 1) * x.var(ddof=1) + (y.size - 1) * y.var(ddof=1)) / (x.size + y.size - 2))
    return float((x.mean() - y.mean()) / pooled) if pooled > 0 else NAN


def compare(a: Sequence[float], b: Sequence[float]) -> Comparison:
    """Welch's t-test, Mann–Whitney U and both effect sizes of ``a`` against ``b``."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.size < 2 or y.size < 2:
        return Comparison(int(x.size), int(y.size), float(x.mean()) if x.size else NAN, float(y.mean()) if y.size else NAN,
                          NAN, NAN, NAN, NAN, NAN, NAN, NAN)
    st = _scipy_stats()
    with warnings.catch_warnings():
        # Nearly constant samples make scipy warn about precision; the NaN handling below covers them.
        warnings.simplefilter("ignore", RuntimeWarning)
        if x.var(ddof=1) == 0 and y.var(ddof=1) == 0:
            t, df, p = NAN, NAN, NAN
        else:
            welch = st.ttest_ind(x, y, equal_var=False)
            t, df, p = float(welch.statistic), float(welch.df), float(welch.pvalue)
        mwu = st.mannwhitneyu(x, y, alternative="two-sided")
    u = float(mwu.statistic)
    return Comparison(int(x.size), int(y.size), float(x.mean()), float(y.mean()), t, df, p, u, float(mwu.pvalue),
                      cohen_d(x, y), 2.0 * u / (x.size * y.size) - 1.0)


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
