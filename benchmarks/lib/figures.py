"""Progress lines and the summary of a sample, as every benchmark prints them."""

from __future__ import annotations

import sys

import numpy as np


def log(*args: object) -> None:
    """A progress line on stderr (stdout carries the JSON)."""
    print(*args, file=sys.stderr, flush=True)


def summary(
    values: list[float], *, percentiles: tuple[int, ...] = (50, 99), scale: float = 1.0, digits: int = 2
) -> dict[str, float]:
    """n, the given percentiles (``p50``...), mean and max of ``values`` times ``scale`` (e.g. 1000
    for s → ms), rounded to ``digits``; ``{"n": 0}`` for no values."""
    if not values:
        return {"n": 0}
    a = np.asarray(values, dtype=float) * scale
    out: dict[str, float] = {"n": int(a.size)}
    out.update({f"p{q}": round(float(np.percentile(a, q)), digits) for q in percentiles})
    out.update({"mean": round(float(a.mean()), digits), "max": round(float(a.max()), digits)})
    return out
