"""The map sweep's heatmaps and its section of REPORT.md: where, over the human's task length ×
the cost of an interruption, ARROCH's difference to each baseline is significant.

One PNG per metric (``map_team_completion_time.png``, ``map_sum_of_times.png``,
``map_door_openings.png``), one panel per baseline: each cell is ARROCH − baseline, the estimate of
the deciding test (the Hodges–Lehmann estimate for times, the mean difference for counts), annotated
with it, the deciding test's interval at its Holm level (:mod:`.comparisons`) and a mark from the
Holm-adjusted p-values (``*`` < 0.05, ``**`` < 0.01, ``***`` < 0.001 for the primary test; ``≈``
equivalent within the margin). The colour map diverges around 0 (blue: ARROCH lower), on
one scale for both panels so they compare. Matplotlib runs headless (Agg).
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display: files only (must precede pyplot)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import CenteredNorm  # noqa: E402

from .comparisons import (  # noqa: E402
    ALPHA,
    DOOR_OPENINGS,
    EQUIVALENT,
    HIGHER,
    LOWER,
    NO_DATA,
    NOT_SIGNIFICANT,
    SUM_OF_TIMES,
    TEAM_TIME,
    Metric,
    Test,
    equivalent,
    format_p_value,
    interval_label,
)
from .design import format_p  # noqa: E402
from .plots import LABELS  # noqa: E402
from .results import Results  # noqa: E402

MAP_METRICS = (TEAM_TIME, SUM_OF_TIMES, DOOR_OPENINGS)


def _axes(results: Results) -> tuple[list[float], list[float]]:
    """Task lengths (rows) and interruption costs (columns), in the sweep's order."""
    tasks: list[float] = []
    costs: list[float] = []
    for task, cost in results.levels:  # type: ignore[misc]
        tasks += [task] if task not in tasks else []
        costs += [cost] if cost not in costs else []
    return tasks, costs


def mark(test: Test) -> str:
    """The cell's significance mark (module docstring)."""
    p = test.primary_p_holm
    if test.outcome in (LOWER, HIGHER):
        return ("***" if p < 0.001 else "**" if p < 0.01 else "*") + ("≈" if test.within_margin else "")
    return "≈" if test.outcome == EQUIVALENT else ""


def _by_cell(tests: list[Test], baseline: str) -> dict[tuple[float, float], Test]:
    return {t.level: t for t in tests if t.baseline == baseline}  # type: ignore[misc]


def plot_map(results: Results, metric: Metric, tests: list[Test], out: Path) -> Path:
    tasks, costs = _axes(results)
    panels = sorted({t.baseline for t in tests}, key=results.methods.index)
    grids = {b: np.full((len(tasks), len(costs)), np.nan) for b in panels}
    for b in panels:
        for (task, cost), t in _by_cell(tests, b).items():
            if t.result.n >= 2 and t.interval is not None:
                grids[b][tasks.index(task), costs.index(cost)] = t.interval.estimate
    finite = [abs(v) for g in grids.values() for v in g.flat if not math.isnan(v)]
    halfrange = max(finite) if finite and max(finite) > 0 else 1.0
    norm = CenteredNorm(vcenter=0.0, halfrange=halfrange)
    cmap = plt.get_cmap("RdBu_r").with_extremes(bad="0.85")  # grey: no data
    fig, axes = plt.subplots(
        1,
        max(1, len(panels)),
        figsize=(1.2 + 2.1 * len(costs) * max(1, len(panels)), 1.6 + 0.9 * len(tasks)),
        dpi=120,
        squeeze=False,
        sharey=True,
        layout="constrained",
    )
    image = None
    unit = f" ({metric.unit})" if metric.unit else ""
    for ax, b in zip(axes[0], panels, strict=True):
        image = ax.imshow(np.ma.masked_invalid(grids[b]), cmap=cmap, norm=norm, origin="lower", aspect="auto")
        for (task, cost), t in _by_cell(tests, b).items():
            i, j = tasks.index(task), costs.index(cost)
            if t.result.n < 2 or t.interval is None:
                text, dark = "n/a", False
            else:
                estimate, interval = t.interval_text().split(" ", 1)
                text = f"{estimate}{mark(t)}\n{interval}"
                dark = abs(norm(t.interval.estimate) - 0.5) > 0.3
            ax.text(j, i, text, ha="center", va="center", fontsize=7, color="white" if dark else "black")
        ax.set_xticks(range(len(costs)), [format_p(c) for c in costs])
        ax.set_yticks(range(len(tasks)), [format_p(w) for w in tasks])
        ax.set_xlabel("Interruption cost (s)")
        ax.set_title(f"ARROCH − {LABELS.get(b, b)}", fontsize=10)
    axes[0][0].set_ylabel("Human's mean task length (s)")
    if image is not None:
        fig.colorbar(image, ax=list(axes[0]), shrink=0.9, label=f"{interval_label(metric, short=True)}{unit}")
    fig.suptitle(f"{metric.label.capitalize()}: ARROCH − baseline, paired (blue: ARROCH lower)", fontsize=10)
    fig.text(
        0.01,
        -0.02,
        f"{interval_label(metric)} of the paired differences; Holm-adjusted {metric.primary_label}: * < {ALPHA:g}, "
        f"** < 0.01, *** < 0.001; ≈ {equivalent(metric)} (Holm-adjusted TOST)",
        ha="left",
        va="top",
        fontsize=7,
        color="0.3",
    )
    path = out / f"map_{metric.name}.png"
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_maps(results: Results, tested: dict[str, list[Test]], out: Path) -> list[Path]:
    return [plot_map(results, m, tested[m.name], out) for m in MAP_METRICS if tested.get(m.name)]


# ---------------------------------------------------------------------------- REPORT.md


def _cell(t: Test) -> str:
    return "n/a" if t.result.n < 2 else t.interval_text()


def _verdict(t: Test) -> str:
    """The verdict with the Holm-adjusted p that decided it (the TOST's for an equivalence)."""
    if t.outcome == EQUIVALENT:
        return f"{t.verdict} (TOST {format_p_value(t.tost_p_holm)})"
    return f"{t.verdict} ({format_p_value(t.primary_p_holm)})"


def _table(results: Results, metric: Metric, tests: list[Test]) -> list[str]:
    panels = sorted({t.baseline for t in tests}, key=results.methods.index)
    head = ["task (s)", "cost (s)", "pairs (per baseline)"]
    for b in panels:
        head += [f"ARROCH − {LABELS.get(b, b)}: {interval_label(metric)}", "verdict (Holm p)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for level in results.levels:
        mine = {t.baseline: t for t in tests if t.level == level}
        if not mine:
            continue
        row = [format_p(level[0]), format_p(level[1]), "/".join(str(mine[b].result.n) for b in panels if b in mine)]  # type: ignore[index]
        for b in panels:
            t = mine.get(b)
            row += ["–", "–"] if t is None else [_cell(t), _verdict(t)]
        lines.append("| " + " | ".join(row) + " |")
    return lines


def _where(tests: list[Test]) -> str:
    return "; ".join(f"task {format_p(t.level[0])} s / cost {format_p(t.level[1])} s: {_cell(t)}" for t in tests)  # type: ignore[index]


def reading(results: Results, tested: dict[str, list[Test]]) -> str:
    """The map in one paragraph, in numbers: per metric and baseline, which cells are significantly
    lower, higher or equivalent, and how that changes with the interruption cost."""
    _, costs = _axes(results)
    sentences = []
    for metric in MAP_METRICS:
        tests = tested.get(metric.name) or []
        for b in sorted({t.baseline for t in tests}, key=results.methods.index):
            mine = [t for t in tests if t.baseline == b]
            groups = {
                v: [t for t in mine if t.outcome == v] for v in (LOWER, HIGHER, EQUIVALENT, NOT_SIGNIFICANT, NO_DATA)
            }
            inside = sum(t.within_margin for t in groups[LOWER] + groups[HIGHER])
            by_cost = ", ".join(
                f"{sum(1 for t in groups[LOWER] if t.level[1] == c)}/{sum(1 for t in mine if t.level[1] == c)}"  # type: ignore[index]
                for c in costs
            )
            parts = [
                f"**{metric.label.capitalize()}, ARROCH − {LABELS.get(b, b)}** (Δ in {metric.unit or 'openings'}): "
                f"significantly lower in {len(groups[LOWER])} of {len(mine)} cells"
                + (f" ({_where(groups[LOWER])})" if groups[LOWER] else "")
                + f" — by interruption cost {'/'.join(format_p(c) for c in costs)} s: {by_cost}",
                f"significantly higher in {len(groups[HIGHER])}"
                + (f" ({_where(groups[HIGHER])})" if groups[HIGHER] else ""),
                f"{equivalent(metric)} in {len(groups[EQUIVALENT])}"
                + (f" (and {inside} of the significant ones within the margin too)" if inside else ""),
                f"not significant in {len(groups[NOT_SIGNIFICANT])}",
            ]
            if groups[NO_DATA]:
                parts.append(f"no data in {len(groups[NO_DATA])}")
            sentences.append("; ".join(parts) + ".")
    return " ".join(sentences)


def map_section(results: Results, tested: dict[str, list[Test]]) -> list[str]:
    if not any(tested.get(m.name) for m in MAP_METRICS):
        return ["## Map: where feedback pays", "", "Not available: the sweep needs ARROCH and a baseline.", ""]
    out = [
        "## Map: where feedback pays",
        "",
        "ARROCH − baseline per cell (task length × interruption cost): the deciding test's estimate and interval at "
        "its Holm level (Hodges–Lehmann with its Wilcoxon interval for times, the mean with its sign-flip interval "
        "for counts); verdicts from the Holm-adjusted p-values over each metric's family (all cells × baselines), as "
        "in the tests above. Negative: ARROCH lower.",
        "",
        "**Reading.** " + reading(results, tested),
        "",
    ]
    for metric in MAP_METRICS:
        tests = tested.get(metric.name)
        if tests:
            out += [
                f"### {metric.label}" + (f" ({metric.unit})" if metric.unit else ""),
                "",
                *_table(results, metric, tests),
                "",
            ]
    return out
