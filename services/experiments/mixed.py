"""A mixed-effects model of a population sweep: the method fixed, the person random.

Each simulated person (a point of the ``population`` sweep) runs every method on several missions.
The paired tests (:mod:`.comparisons`) pool the pairs of all persons; beside them, per metric,

    y[person, method, mission] = β_method + u_person + ε,   u ~ N(0, σ²_person), ε ~ N(0, σ²)

fitted by restricted maximum likelihood (statsmodels ``MixedLM``, a random intercept per person),
with ARROCH as the reference level: each baseline's coefficient is baseline − ARROCH, reported here
as ARROCH − baseline (its sign flipped, the same convention as the paired tests) with its 95 % Wald
interval and p-value. The person variance says how much of the spread is between people rather than
between missions. A fit that does not converge is reported as such, never silently.

statsmodels is imported on first use.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field

REFERENCE = "arroch"


@dataclass(frozen=True)
class Effect:
    baseline: str
    estimate: float  # ARROCH − baseline
    low: float  # 95 % Wald interval
    high: float
    p: float


@dataclass(frozen=True)
class MixedFit:
    metric: str
    persons: int
    observations: int
    effects: list[Effect] = field(default_factory=list)
    person_sd: float = math.nan  # sd of the persons' random intercepts
    residual_sd: float = math.nan
    converged: bool = True
    note: str = ""


@dataclass(frozen=True)
class Observation:
    person: int
    method: str
    value: float


def fit_mixed(metric: str, observations: Iterable[Observation]) -> MixedFit:
    """The model of the module docstring on ``observations``; a note instead of effects when it cannot be fitted."""
    rows = [o for o in observations if o.value is not None and math.isfinite(o.value)]
    persons = sorted({o.person for o in rows})
    methods = sorted({o.method for o in rows})
    if REFERENCE not in methods or len(methods) < 2 or len(persons) < 2:
        return MixedFit(metric, len(persons), len(rows), note="needs ARROCH, a baseline and at least two persons")
    import numpy as np
    from statsmodels.regression.mixed_linear_model import MixedLM
    from statsmodels.tools.sm_exceptions import ConvergenceWarning

    baselines = [m for m in methods if m != REFERENCE]
    y = np.array([o.value for o in rows], dtype=float)
    # Fixed effects: an intercept (ARROCH) and one indicator per baseline (treatment coding).
    x = np.column_stack([np.ones(len(rows))] + [[1.0 if o.method == b else 0.0 for o in rows] for b in baselines])
    groups = np.array([o.person for o in rows])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        try:
            result = MixedLM(y, x, groups).fit(reml=True)
        except (ValueError, np.linalg.LinAlgError) as exc:
            return MixedFit(metric, len(persons), len(rows), converged=False, note=f"not fitted: {exc}")
    converged = bool(getattr(result, "converged", True)) and not any(
        issubclass(w.category, ConvergenceWarning) for w in caught
    )
    params, bse, pvalues = np.asarray(result.fe_params), np.asarray(result.bse_fe), np.asarray(result.pvalues)
    effects = []
    for i, b in enumerate(baselines, start=1):
        estimate, se = -float(params[i]), float(bse[i])
        effects.append(Effect(b, estimate, estimate - 1.959964 * se, estimate + 1.959964 * se, float(pvalues[i])))
    return MixedFit(
        metric,
        len(persons),
        len(rows),
        effects,
        person_sd=math.sqrt(max(float(np.asarray(result.cov_re)[0, 0]), 0.0)),
        residual_sd=math.sqrt(float(result.scale)),
        converged=converged,
        note="" if converged else "the fit did not converge: read its numbers with care",
    )
