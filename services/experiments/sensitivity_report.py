"""The sensitivity analysis's report: ``REPORT.md``, ``sensitivity.json`` and its figures, from its two
stage folders (:mod:`.sensitivity`). ``arroch experiment report DIR`` rebuilds it."""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display: files only (must precede pyplot)
import matplotlib.pyplot as plt  # noqa: E402

from .plots import LABELS  # noqa: E402
from .results import Results, load_results, statuses  # noqa: E402
from .sensitivity import (  # noqa: E402
    DESIGN_FILE,
    SCREEN,
    SUMMARY_FILE,
    Design,
    OutputAnalysis,
    analyse,
)
from .store import JsonlStore  # noqa: E402


def strict_json(data: object) -> str:
    """``data`` as standard JSON: a NaN or infinite number (an index SALib could not compute, a
    Morris-only output's Sobol columns) is ``null``, since JSON has no NaN and strict readers
    (JavaScript's, jq) refuse Python's ``NaN``."""

    def finite(value: object) -> object:
        if isinstance(value, float):
            return value if math.isfinite(value) else None
        if isinstance(value, dict):
            return {key: finite(item) for key, item in value.items()}
        if isinstance(value, list | tuple):
            return [finite(item) for item in value]
        return value

    return json.dumps(finite(data), indent=1, default=str, allow_nan=False)


def _f(value: float, digits: int = 1) -> str:
    return "n/a" if value is None or math.isnan(value) else f"{value:+.{digits}f}"


def _u(value: float, digits: int = 1) -> str:
    return "n/a" if value is None or math.isnan(value) else f"{value:.{digits}f}"


def _title(a: OutputAnalysis) -> str:
    label = {"team_completion_time": "team completion time", "sum_of_times": "sum of times"}[a.metric]
    return f"{label}, ARROCH − {LABELS.get(a.baseline, a.baseline)}"


def plot_morris(analyses: list[OutputAnalysis], out: Path) -> Path:
    fig, axes = plt.subplots(2, 2, figsize=(10, 8), dpi=120, layout="constrained")
    for ax, a in zip(axes.flat, analyses, strict=False):
        xs = [e.mu_star for e in a.effects]
        ys = [0.0 if math.isnan(e.sigma) else e.sigma for e in a.effects]  # one trajectory: no σ, drawn at 0
        ax.errorbar(xs, ys, xerr=[e.mu_star_conf for e in a.effects], fmt="o", color="#2166ac", ms=4, capsize=2)
        for e, y in zip(a.effects, ys, strict=True):
            if not math.isnan(e.mu_star):
                marker = "−" if e.mu < 0 else "+"
                ax.annotate(
                    f"{e.name} ({marker})", (e.mu_star, y), fontsize=7, xytext=(3, 3), textcoords="offset points"
                )
        top = max([v for v in xs + ys if not math.isnan(v)] or [1.0])
        ax.plot([0, top], [0, top], ls="--", lw=0.7, color="0.5")  # sigma = mu*: interactions as large as the effect
        ax.set_xlabel("μ* (s over the factor's range): size of its effect")
        ax.set_ylabel(
            "σ (s): interactions, non-linearity"
            + (" (n/a: at 0)" if any(math.isnan(e.sigma) for e in a.effects) else "")
        )
        ax.set_title(_title(a), fontsize=10)
        ax.grid(alpha=0.3)
    fig.suptitle("Morris screening (paired by common random numbers); (+/−): sign of μ, the mean effect", fontsize=10)
    path = out / "morris_mu_star_sigma.png"
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_sobol(analyses: list[OutputAnalysis], out: Path) -> Path:
    fig, axes = plt.subplots(2, 2, figsize=(10, 7), dpi=120, layout="constrained", sharey=True)
    for ax, a in zip(axes.flat, analyses, strict=False):
        names = [e.name for e in a.effects]
        xs = range(len(names))
        ax.bar([x - 0.2 for x in xs], [e.s1 for e in a.effects], 0.4, yerr=[e.s1_conf for e in a.effects], label="S1")
        ax.bar([x + 0.2 for x in xs], [e.st for e in a.effects], 0.4, yerr=[e.st_conf for e in a.effects], label="ST")
        ax.set_xticks(list(xs), names, fontsize=8)
        ax.set_title(_title(a), fontsize=10)
        ax.axhline(0, color="0.3", lw=0.6)
        ax.legend(frameon=False, fontsize=8)
    fig.suptitle("Sobol indices (first order S1, total ST) with 95 % bootstrap intervals", fontsize=10)
    path = out / "sobol_indices.png"
    fig.savefig(path)
    plt.close(fig)
    return path


def _reading(a: OutputAnalysis, top: int = 3) -> str:
    ranked = sorted((e for e in a.effects if not math.isnan(e.mu_star)), key=lambda e: -e.mu_star)[:top]
    parts = [
        f"**{_title(a)}**: mean {_f(a.mean)} s over {a.points} points, ARROCH lower at "
        f"{_u(100 * a.lower_share, 0)} % of them"
        + (f" ({a.missing} point(s) without a complete pair took the mean)" if a.missing else "")
    ]
    for e in ranked:
        parts.append(
            f"{e.name}: μ* {_u(e.mu_star)} ± {_u(e.mu_star_conf)} s, μ {_f(e.mu)} s, σ {_u(e.sigma)} s; "
            f"mean difference {_f(e.low_half)} s in its lower half, {_f(e.high_half)} s in its upper half"
        )
    return "; ".join(parts) + "."


def _morris_table(a: OutputAnalysis) -> list[str]:
    lines = [
        "| factor | μ* ± 95 % (s over its range) | μ (s) | σ (s) | mean Δ, lower half (s) | mean Δ, upper half (s) |",
        "|---|---|---|---|---|---|",
    ]
    for e in sorted(a.effects, key=lambda e: -(e.mu_star if not math.isnan(e.mu_star) else -1)):
        lines.append(
            f"| {e.name} | {_u(e.mu_star)} ± {_u(e.mu_star_conf)} | {_f(e.mu)} | {_u(e.sigma)} | {_f(e.low_half)} "
            f"| {_f(e.high_half)} |"
        )
    return lines


def _sobol_table(a: OutputAnalysis) -> list[str]:
    lines = ["| factor | S1 ± 95 % | ST ± 95 % |", "|---|---|---|"]
    lines += [
        f"| {e.name} | {_u(e.s1, 2)} ± {_u(e.s1_conf, 2)} | {_u(e.st, 2)} ± {_u(e.st_conf, 2)} |" for e in a.effects
    ]
    return lines


def _trials(results: Results) -> str:
    counts = statuses(results.trials)
    wall = sum(float(r.get("wall_time", 0.0)) for r in results.runs)
    return (
        f"{len(results.trials)} trials ("
        + ", ".join(f"{n} {s}" for s, n in sorted(counts.items()))
        + f"), {wall / 60:.1f} min"
    )


def anticipation_note(folder: Path, design: Design) -> str:
    """Whether the simulator reported anticipated trips (it must feed the plans to the human model)."""
    if "anticipation" not in design.names and not design.fixed.get("anticipation"):
        return ""
    store = JsonlStore(folder / "metrics.jsonl")
    records = store.load() if store.path.exists() else []
    if any("anticipated" in (r["metrics"].get("human") or {}) for r in records):
        return ""
    return (
        "**Anticipation had no effect in these trials**: the simulator does not report anticipated trips, i.e. it "
        "does not yet pass the robots' planned arrivals to the human model; its μ* measures nothing here."
    )


def build_sensitivity_report(folder: Path, seed: int = 0) -> list[Path]:
    """Write the report of the sensitivity analysis in ``folder`` (module docstring)."""
    folder = Path(folder)
    written: list[Path] = []
    summary: dict[str, object] = {}
    lines = [
        "# Sensitivity analysis: which parameters decide ARROCH's differences",
        "",
        "Outputs per point: the mean over its replicates of the paired differences ARROCH − No-feedback and "
        "ARROCH − No-comm on team completion time and on the sum of all agents' times. Every point meets the same "
        "buildings and human draws for one replicate (common random numbers). Method: `services/experiments/"
        "sensitivity.py`.",
        "",
        "## Factors",
        "",
        "| factor | range | held at | source |",
        "|---|---|---|---|",
        *(f"| {r.name} | {r.low:g}–{r.high:g} | {r.nominal:g} | {r.source} |" for r in SCREEN),
        "",
    ]
    for stage in ("morris", "sobol"):
        path = folder / stage
        if not (path / DESIGN_FILE).exists() or not (path / "trials.csv").exists():
            continue
        design = Design.load(path)
        results = load_results(path)
        analyses = analyse(design, results, seed)
        summary[stage] = {"design": asdict(design) | {"x": len(design.x)}, "outputs": [asdict(a) for a in analyses]}
        spec = results.spec
        lines += [
            f"## {stage.capitalize()} stage",
            "",
            f"{len(design.x)} points × {len(spec.methods) if spec else 3} methods × {spec.trials if spec else '?'} "
            f"replicate(s); {spec.robots[0] if spec else '?'} robots × {spec.objects if spec else '?'} objects, "
            f"detour buildings; {_trials(results)}."
            + (
                f" Varied: {', '.join(design.names)}; held: "
                + ", ".join(f"{k} = {v:g}" for k, v in design.fixed.items())
                if design.fixed
                else ""
            ),
            "",
        ]
        note = anticipation_note(path, design)
        if note:
            lines += [note, ""]
        if stage == "morris":
            figure = plot_morris(analyses, folder)
            lines += [
                "**Reading.** " + " ".join(_reading(a) for a in analyses),
                "",
                f"![{figure.stem}]({figure.name})",
                "",
            ]
            for a in analyses:
                lines += [f"### {_title(a)}", "", *_morris_table(a), ""]
        else:
            figure = plot_sobol(analyses, folder)
            lines += [
                "Sobol indices of the factors the screening ranked highest, with their bootstrap intervals; with few "
                "base points the intervals are wide and a negative or above-1 index is noise.",
                "",
                f"![{figure.stem}]({figure.name})",
                "",
            ]
            for a in analyses:
                lines += [f"### {_title(a)}", "", *_sobol_table(a), ""]
        written.append(figure)
    (folder / SUMMARY_FILE).write_text(strict_json(summary) + "\n", encoding="utf-8")
    discussion = folder / "discussion.md"
    lines += [
        "## Discussion",
        "",
        discussion.read_text(encoding="utf-8").strip() if discussion.exists() else "None yet.",
        "",
    ]
    (folder / "REPORT.md").write_text("\n".join(lines).rstrip() + "\n", encoding="utf-8")
    return [*written, folder / SUMMARY_FILE, folder / "REPORT.md"]
