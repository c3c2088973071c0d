"""The report's bar figures of the robots and laziness sweeps, shaped like the paper's: (a) door
openings and (b) team completion time against the swept variable, plus (c) the sum of all agents'
completion times (the paper's real-world measure), one bar per method at each level, with 95 %
confidence intervals. (The map's heatmaps are drawn by :mod:`.maps`.)

One PNG per panel, named after what it shows (``door_openings_vs_robots.png``, ...). Bars are
means of the completed trials; the whiskers are the t intervals of :func:`.stats.summarize`; a
condition without completed trials has no bar. Matplotlib runs headless (Agg).
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display: files only (must precede pyplot)
import matplotlib.pyplot as plt  # noqa: E402

from .results import Results  # noqa: E402
from .stats import summarize  # noqa: E402

COLORS = {"arroch": "#1b7837", "no-feedback": "#2166ac", "no-comm": "#b2182b"}
LABELS = {"arroch": "ARROCH", "no-feedback": "No-feedback", "no-comm": "No-comm"}
PANELS = (
    ("door_openings", "Door openings by the human", "(a) Human workload"),
    ("team_completion_time", "Team completion time (s)", "(b) Team efficiency (slowest agent)"),
    ("sum_of_times", "Sum of all agents' completion times (s)", "(c) Team efficiency (sum of times)"),
)


def _name(metric: str, results: Results) -> str:
    if results.points:
        return f"{metric}_by_point.png"
    return f"{metric}_vs_{'robots' if results.kind == 'robots' else 'p'}.png"


def _tick(results: Results, level: object) -> str:
    if results.points:
        return results.level_label(level).replace(", ", "\n")  # type: ignore[arg-type]
    return f"{int(level)}" if results.kind == "robots" else f"{level:g}"  # type: ignore[call-overload]


def _axis(results: Results) -> str:
    if results.points:
        return results.variable
    return "Number of robots" if results.kind == "robots" else "Door-opening probability (lower = lazier human)"


def plot_metric(results: Results, metric: str, ylabel: str, title: str, out: Path) -> Path:
    levels = results.levels
    methods = results.methods
    width = 0.8 / max(1, len(methods))
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=120)
    for i, method in enumerate(methods):
        xs, means, errors = [], [], []
        for j, level in enumerate(levels):
            s = summarize(results.values(method, level, metric))
            if s.n == 0:
                continue
            xs.append(j + (i - (len(methods) - 1) / 2) * width)
            means.append(s.mean)
            errors.append(0.0 if math.isnan(s.half_width) else s.half_width)
        ax.bar(
            xs,
            means,
            width,
            yerr=errors,
            capsize=3,
            label=LABELS.get(method, method),
            color=COLORS.get(method, None),
            edgecolor="black",
            linewidth=0.5,
            error_kw={"linewidth": 0.9},
        )
    ax.set_xticks(range(len(levels)))
    ax.set_xticklabels([_tick(results, v) for v in levels], fontsize=8 if results.points else None)
    ax.set_xlabel(_axis(results))
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(axis="y", alpha=0.3)
    ax.set_axisbelow(True)
    ax.legend(frameon=False)
    fig.text(
        0.99,
        0.01,
        "bars: mean of completed trials; whiskers: 95 % CI",
        ha="right",
        va="bottom",
        fontsize=7,
        color="0.4",
    )
    fig.tight_layout()
    path = out / _name(metric, results)
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_all(results: Results, out: Path) -> list[Path]:
    return [plot_metric(results, metric, ylabel, title, out) for metric, ylabel, title in PANELS]
