"""The report's figures (PNG), the paper's three panels of its real-world results:

- each trial's human completion time against the robots' summed completion times, one colour per
  condition, with each condition's 2-D standard-deviation ellipse (centred on the means; its axes
  along the eigenvectors of the sample covariance, half-lengths the square roots of its eigenvalues);
- a histogram of team completion times per condition, on shared bins;
- the Likert items' means per condition with their 95 % t intervals.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display on a study laptop's terminal or a CI machine

import matplotlib.pyplot as plt  # noqa: E402 - after choosing the backend
import numpy as np  # noqa: E402
from matplotlib.patches import Ellipse  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from .stats import Estimate  # noqa: E402

COLORS = {"arroch": "#1b9e77", "map": "#d95f02", "no-feedback": "#7570b3"}
DPI = 150


def _color(condition: str, index: int) -> str:
    return COLORS.get(condition, f"C{index}")


def sd_ellipse(points: np.ndarray) -> tuple[tuple[float, float], float, float, float] | None:
    """(centre, width, height, angle in degrees) of the 1-SD ellipse of ``points`` (n x 2); None for n < 3."""
    if points.shape[0] < 3:
        return None
    cov = np.cov(points, rowvar=False)
    values, vectors = np.linalg.eigh(cov)
    values = np.clip(values, 0.0, None)
    major = vectors[:, 1]
    angle = math.degrees(math.atan2(major[1], major[0]))
    centre = (float(points[:, 0].mean()), float(points[:, 1].mean()))
    return centre, 2 * math.sqrt(values[1]), 2 * math.sqrt(values[0]), angle


def times_scatter(points: Mapping[str, Sequence[tuple[float, float]]], path: Path) -> None:
    fig, ax = plt.subplots(figsize=(5.0, 4.2))
    for i, (condition, pts) in enumerate(points.items()):
        if not pts:
            continue
        arr = np.asarray(pts, dtype=float)
        color = _color(condition, i)
        ax.scatter(arr[:, 0], arr[:, 1], color=color, label=f"{condition} (n={len(arr)})", s=28, zorder=3)
        ell = sd_ellipse(arr)
        if ell is not None:
            centre, width, height, angle = ell
            ax.add_patch(Ellipse(centre, width, height, angle=angle, fill=False, color=color, lw=1.5))
            ax.plot(*centre, marker="+", color=color, ms=10)
    ax.set_xlabel("human completion time (s)")
    ax.set_ylabel("robots' summed completion times (s)")
    ax.set_title("Individual completion times (ellipses: 2-D SD)")
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def team_histogram(values: Mapping[str, Sequence[float]], path: Path, bins: int = 8) -> None:
    fig, ax = plt.subplots(figsize=(5.0, 3.6))
    everything = [v for vs in values.values() for v in vs]
    if everything:
        lo, hi = min(everything), max(everything)
        edges = np.linspace(lo, hi if hi > lo else lo + 1.0, bins + 1)
        data = [list(vs) for vs in values.values()]
        colors = [_color(c, i) for i, c in enumerate(values)]
        labels = [f"{c} (n={len(vs)})" for c, vs in values.items()]
        ax.hist(data, bins=edges, color=colors, label=labels)
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, "no completed mission", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("team completion time (s)")
    ax.set_ylabel("trials")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title("Team completion time")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def likert_means(means: Mapping[str, Mapping[str, Estimate]], path: Path, scale: tuple[int, int] = (1, 5)) -> None:
    """``means[item][condition]``: bars of the means with 95 % interval whiskers."""
    items = list(means)
    conditions = list(dict.fromkeys(c for item in items for c in means[item]))
    fig, ax = plt.subplots(figsize=(max(4.0, 1.1 * len(items) + 1.5), 3.6))
    width = 0.8 / max(1, len(conditions))
    x = np.arange(len(items))
    for i, condition in enumerate(conditions):
        ests = [means[item].get(condition) for item in items]
        heights = [e.value if e is not None else np.nan for e in ests]
        low = [e.value - e.low if e is not None and not math.isnan(e.low) else 0.0 for e in ests]
        high = [e.high - e.value if e is not None and not math.isnan(e.high) else 0.0 for e in ests]
        ax.bar(
            x + (i - (len(conditions) - 1) / 2) * width,
            heights,
            width,
            yerr=[low, high],
            capsize=3,
            color=_color(condition, i),
            label=condition,
        )
    ax.set_xticks(x, items)
    ax.set_ylim(scale[0] - 1 if scale[0] > 0 else 0, scale[1] + 0.5)
    ax.set_ylabel(f"mean score ({scale[0]}-{scale[1]}), 95 % CI")
    ax.set_title("Questionnaire")
    if conditions:
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, "no answers", ha="center", va="center", transform=ax.transAxes)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
