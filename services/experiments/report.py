"""``arroch experiment report DIR``: everything a results folder says, rebuilt from its CSV.

Writes into DIR:

- ``summary.csv`` / ``summary.md``: per condition, the trials by status and the mean with its 95 %
  confidence interval of every figure (completed trials only);
- ``tests.csv``: ARROCH against each baseline per level, for door openings and team completion
  time: Welch's t-test, Mann–Whitney U, Cohen's d, rank-biserial correlation, Holm-adjusted p;
- the figures of :mod:`.plots`;
- ``REPORT.md``: the above, the human model's parameters (``params.json``), the paper's claims
  checked (:mod:`.claims`), what drives team completion time, the wall time of the sweep and where
  it went (``timing.csv``, ``runs.json``), and ``discussion.md`` (written by a person, if present).

Only the CSV is needed; the side files add their sections when present.
"""

from __future__ import annotations

import csv
import json
import logging
import math
from pathlib import Path
from typing import Any, Iterable

from .claims import Claim, check_claims, format_p_value
from .params import write_params
from .results import METRICS, ReportError, Results, load_results, statuses
from .stats import Summary, compare, holm, summarize
from .store import JsonlStore

log = logging.getLogger("arroch.experiment")

TESTED = (("door_openings", "door openings"), ("team_completion_time", "team completion time (s)"))
SUMMARY_COLUMNS = (("team_completion_time", "team completion (s)"), ("door_openings", "door openings"),
                   ("slowest_robot_time", "slowest robot (s)"), ("human_completion_time", "human done (s)"),
                   ("feedback_sent", "feedback sent"), ("feedback_accepted", "feedback accepted"),
                   ("replans", "replans"))
STATUSES = ("ok", "unfinished", "timeout", "error")

__all__ = ["ReportError", "build_report"]


# ---------------------------------------------------------------------------- formatting

def _num(value: float, digits: int = 3) -> str:
    return "" if value is None or math.isnan(value) else f"{value:.{digits}f}"


def _mean_ci(s: Summary, digits: int = 1) -> str:
    if s.n == 0:
        return "–"
    if math.isnan(s.ci_low):
        return f"{s.mean:.{digits}f}"
    return f"{s.mean:.{digits}f} [{s.ci_low:.{digits}f}, {s.ci_high:.{digits}f}]"


def _level(results: Results, level: float) -> str:
    return str(int(level)) if results.kind == "robots" else f"{level:g}"


def _table(header: list[str], rows: Iterable[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines


def _write_csv(path: Path, header: list[str], rows: Iterable[list[str]]) -> Path:
    with open(path, "w", encoding="utf-8", newline="") as out:
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(header)
        writer.writerows(rows)
    return path


# ---------------------------------------------------------------------------- tables

def summary_rows(results: Results) -> tuple[list[str], list[list[str]]]:
    header = ["method", "robots", "objects", "door_probability", "trials", *STATUSES]
    for metric in METRICS:
        header += [f"{metric}_mean", f"{metric}_ci_low", f"{metric}_ci_high", f"{metric}_n"]
    rows = []
    for level, method, trials in results.conditions():
        counts = statuses(trials)
        row = [method, str(trials[0].robots), str(trials[0].objects), f"{trials[0].p:g}", str(len(trials)),
               *(str(counts.get(s, 0)) for s in STATUSES)]
        for metric in METRICS:
            s = summarize(results.values(method, level, metric))
            row += [_num(s.mean), _num(s.ci_low), _num(s.ci_high), str(s.n)]
        rows.append(row)
    return header, rows


def test_rows(results: Results) -> tuple[list[str], list[list[str]]]:
    header = ["metric", "robots" if results.kind == "robots" else "door_probability", "baseline", "n_arroch", "n_baseline",
              "mean_arroch", "mean_baseline", "difference", "welch_t", "welch_df", "welch_p", "welch_p_holm",
              "mwu_u", "mwu_p", "mwu_p_holm", "cohen_d", "rank_biserial"]
    rows = []
    if "arroch" not in results.methods:
        return header, rows
    baselines = [m for m in results.methods if m != "arroch"]
    for metric, _label in TESTED:
        family = []
        for level in results.levels:
            a = results.values("arroch", level, metric)
            for baseline in baselines:
                b = results.values(baseline, level, metric)
                if len(a) >= 2 and len(b) >= 2:
                    family.append((level, baseline, compare(a, b)))
        welch_holm = holm([c.welch_p for _, _, c in family])
        mwu_holm = holm([c.mwu_p for _, _, c in family])
        for (level, baseline, c), wh, mh in zip(family, welch_holm, mwu_holm):
            rows.append([metric, _level(results, level), baseline, str(c.n_a), str(c.n_b), _num(c.mean_a), _num(c.mean_b),
                         _num(c.diff), _g(c.welch_t), _g(c.welch_df), _g(c.welch_p), _g(wh), _g(c.mwu_u),
                         _g(c.mwu_p), _g(mh), _g(c.cohen_d), _g(c.rank_biserial)])
    return header, rows


def _g(value: float) -> str:
    """A statistic in a CSV cell: six significant digits, empty when undefined."""
    return "" if math.isnan(value) else f"{value:.6g}"


# ---------------------------------------------------------------------------- sections

def _section_trials(results: Results) -> list[str]:
    counts = statuses(results.trials)
    spec = results.spec
    lines = ["## Trials", ""]
    if spec is not None:
        what = (f"team sizes {', '.join(str(n) for n in spec.robots)}, door-opening probability {', '.join(f'{p:g}' for p in spec.ps)}"
                if results.kind == "robots" else
                f"door-opening probabilities {', '.join(f'{p:g}' for p in spec.ps)}, {', '.join(str(n) for n in spec.robots)} robots")
        lines += [f"Methods {', '.join(spec.methods)}; {what}; {spec.objects} object(s) per robot; {spec.trials} trials per "
                  f"condition; base seed {spec.seed}; human model: "
                  + ("the simulator's defaults (the paper's model)" if spec.human_config is None else "a custom --human-config (not the paper's model)")
                  + ".", ""]
    lines.append(f"{len(results.trials)} trials: " + ", ".join(f"{counts.get(s, 0)} {s}" for s in STATUSES) + ". "
                 "Statistics use the completed (`ok`) trials only.")
    codes: dict[str, int] = {}
    for r in results.timing:
        if r.get("code"):
            codes[r["code"]] = codes.get(r["code"], 0) + 1
    if len(codes) == 1:
        lines += ["", f"Every trial ran on the same services' code (fingerprint `{next(iter(codes))}`, see timing.csv)."]
    elif codes:
        lines += ["", f"**The trials ran on {len(codes)} versions of the services' code** (the sources changed during the sweep; "
                  "fingerprint: trials): " + ", ".join(f"`{c}`: {n}" for c, n in codes.items())
                  + ". Trials of different versions are not strictly comparable."]
    failed = [t for t in results.trials if t.status not in ("ok",)]
    if failed:
        lines += ["", "Trials that did not complete (first 10):", ""]
        lines += [f"- {t.method}, {t.robots} robots, p = {t.p:g}, trial {t.trial}: {t.status} — {t.reason}" for t in failed[:10]]
    return lines + [""]


def _section_params(results: Results) -> list[str]:
    params = results.params
    if not params:
        return ["## Human model", "", "No params.json in this folder (it is written when a sweep completes).", ""]
    human = params.get("human", {})
    lines = ["## Human model (as the simulator reported it; not tuned)", "",
             f"Source: {params.get('source', 'params.json')}. Varied per trial: "
             + ", ".join(f"{k} ∈ {{{', '.join(f'{v:g}' for v in vs)}}}" for k, vs in params.get("varied_per_trial", {}).items()) + ".", ""]
    lines += _table(["parameter", "value"], [[k, f"{v:g}" if isinstance(v, float) else str(v)] for k, v in sorted(human.items())])
    other = {k: v for k, v in params.items() if k in ("site_params", "engine")}
    for name, values in other.items():
        lines += ["", f"{name}: " + ", ".join(f"{k} = {v}" for k, v in sorted(values.items()))]
    if params.get("mode") is not None:
        lines += ["", f"clock mode: {params.get('mode')}"]
    if params.get("differs"):
        lines += ["", "**Parameters that differ between trials** (the trials are not comparable on these): "
                  + "; ".join(f"{k}: {v}" for k, v in params["differs"].items())]
    return lines + [""]


def _section_summary(results: Results) -> list[str]:
    head = ["robots" if results.kind == "robots" else "p", "method", "ok / n", *(label for _, label in SUMMARY_COLUMNS), "human slowest"]
    rows = []
    for level, method, trials in results.conditions():
        ok = [t for t in trials if t.ok]
        slowest = [t.human_slowest for t in ok if t.human_slowest is not None]
        row = [_level(results, level), method, f"{len(ok)} / {len(trials)}"]
        for metric, _ in SUMMARY_COLUMNS:
            digits = 1 if metric.endswith("time") else 2
            row.append(_mean_ci(summarize(results.values(method, level, metric)), digits))
        row.append(f"{sum(slowest)}/{len(slowest)}" if slowest else "–")
        rows.append(row)
    return ["## Summary (mean [95 % CI])", "", *_table(head, rows), "",
            "*human slowest*: completed trials in which the human's own task ended last, i.e. set the team's time.", ""]


def _section_tests(results: Results) -> list[str]:
    header, rows = test_rows(results)
    if not rows:
        return ["## ARROCH against each baseline", "", "Not available: the sweep needs ARROCH, a baseline and two completed trials per condition.", ""]
    out = ["## ARROCH against each baseline", "",
           "Two-sided tests per level; negative difference, d and r mean ARROCH is lower. Holm: over all levels and "
           "baselines of one metric.", ""]
    for metric, label in TESTED:
        mine = [r for r in rows if r[0] == metric]
        table = [[r[1], r[2], f"{_f(r[5]):.1f} vs {_f(r[6]):.1f}", f"{_f(r[7]):.1f}", f"{_f(r[8]):.2f} ({_f(r[9]):.1f})",
                  format_p_value(_f(r[10])), format_p_value(_f(r[11])), f"{_f(r[12]):g}", format_p_value(_f(r[13])),
                  f"{_f(r[15]):.2f}", f"{_f(r[16]):.2f}"] for r in mine]
        out += [f"### {label}", "", *_table([header[1], "baseline", "mean ARROCH vs baseline", "difference", "Welch t (df)",
                                              "Welch p", "Holm p", "MWU U", "MWU p", "Cohen's d", "rank-biserial r"], table), ""]
    return out


def _f(text: str) -> float:
    return float(text) if text else float("nan")


def _section_claims(claims: list[Claim]) -> list[str]:
    out = ["## The paper's claims", "",
           "A level is *confirmed* when ARROCH's mean is below each baseline's and Welch's two-sided test gives p < 0.05 "
           "for each; *lower* when the means are below but a test is not significant.", ""]
    for claim in claims:
        out += [f"### {claim.title}: **{claim.verdict}**", "", f"Claim: {claim.statement}", "", claim.detail, ""]
        holm_notes = [f"{level.level:g}/{b}: {format_p_value(p)}" for level in claim.levels for b, p in level.holm_p.items()]
        if holm_notes:
            out += ["Holm-adjusted Welch p (level/baseline): " + ", ".join(holm_notes) + ".", ""]
    return out


def _section_drivers(results: Results) -> list[str]:
    """What sets the team's time: the human's own task, or the robots."""
    ok = [t for t in results.trials if t.ok and t.human_slowest is not None]
    if not ok:
        return []
    lines = ["## What sets the team completion time", ""]
    for method in results.methods:
        mine = [t for t in ok if t.method == method]
        if not mine:
            continue
        human = sum(1 for t in mine if t.human_slowest)
        hs = summarize([t.values["human_completion_time"] for t in mine if t.values["human_completion_time"] is not None])
        rs = summarize([t.values["slowest_robot_time"] for t in mine if t.values["slowest_robot_time"] is not None])
        away = summarize([t.values["human_time_away"] for t in mine if t.values["human_time_away"] is not None])
        lines.append(f"- {method}: the human was the slowest agent in {human} of {len(mine)} completed trials; her task ended at "
                     f"{_mean_ci(hs)} s on average, the last robot's delivery at {_mean_ci(rs)} s; she spent {_mean_ci(away)} s "
                     f"away from her task on doors.")
    return lines + [""]


def _section_time(results: Results) -> list[str]:
    if not results.timing and not results.runs:
        return []
    lines = ["## Wall time", ""]
    if results.runs:
        total = sum(float(r.get("wall_time", 0.0)) for r in results.runs)
        lines.append(f"{len(results.runs)} session(s), {total / 60:.1f} min of wall time in all "
                     + "(" + "; ".join(f"{r.get('started', '?')}: {float(r.get('wall_time', 0)) / 60:.1f} min, {r.get('trials_run')} trials, "
                                      f"{r.get('jobs')} jobs, router per {r.get('router')}, {r.get('ended')}" for r in results.runs) + ").")
        lines.append("")
    rows = [r for r in results.timing if r.get("wall_time")]
    if rows:
        versions = {(t.method, t.robots, t.objects, t.p, t.trial): t.values.get("world_versions") for t in results.trials}

        def mean(name: str, subset: list[dict[str, str]]) -> str:
            vals = [float(r[name]) for r in subset if r.get(name)]
            return f"{sum(vals) / len(vals):.2f}" if vals else "–"

        def per_version(subset: list[dict[str, str]]) -> str:
            """Mission wall time per world version: one lockstep round trip (sim → planner → sim)."""
            pairs = [(float(r["mission_wall_time"]), versions.get((r["method"], int(r["robots"]), int(r["objects"]),
                                                                   float(r["door_probability"]), int(r["trial"]))))
                     for r in subset if r.get("mission_wall_time")]
            pairs = [(w, v) for w, v in pairs if v]
            return f"{1000 * sum(w for w, _ in pairs) / sum(v for _, v in pairs):.0f}" if pairs else "–"

        groups: dict[str, list[dict[str, str]]] = {}
        for r in rows:
            level = r["robots"] if results.kind == "robots" else r["door_probability"]
            groups.setdefault(level, []).append(r)
        head = ["robots" if results.kind == "robots" else "p", "trials", "wall / trial (s)", "services up (s)", "sim start-up + end (s)",
                "mission (s)", "planner solve (s)", "plans", "ms per world version", "shutdown (s)", "sim s per wall s"]
        table = [[level, str(len(g)), mean("wall_time", g), mean("services_up", g), mean("sim_startup", g), mean("mission_wall_time", g),
                  mean("planner_solve_time", g), mean("plans", g), per_version(g), mean("shutdown", g), mean("realtime_factor", g)]
                 for level, g in groups.items()]
        lines += ["Per trial, mean (from timing.csv; trials ran in parallel, so the sweep's wall time is about the sum / jobs). "
                  "*ms per world version*: mission wall time over the world versions the planner had to answer, i.e. "
                  "the cost of one lockstep round trip including the replan.", "",
                  *_table(head, table), ""]
    return lines


def _section_discussion(results: Results) -> list[str]:
    path = results.folder / "discussion.md"
    if not path.exists():
        return ["## Discussion", "", "No discussion.md in this folder yet.", ""]
    return ["## Discussion", "", path.read_text(encoding="utf-8").strip(), ""]


# ---------------------------------------------------------------------------- the whole report

def build_report(folder: Path) -> list[Path]:
    """Write every report file into ``folder``; returns their paths."""
    from .plots import plot_all  # matplotlib only here

    folder = Path(folder)
    results = load_results(folder)
    written = []
    metrics = JsonlStore(folder / "metrics.jsonl")
    if metrics.path.exists():  # the model's parameters, from the same trials
        write_params(folder / "params.json", (r["metrics"] for r in metrics.load()))
        results.params = json.loads((folder / "params.json").read_text(encoding="utf-8"))
        written.append(folder / "params.json")
    header, rows = summary_rows(results)
    written.append(_write_csv(folder / "summary.csv", header, rows))
    summary_md = _section_summary(results)
    (folder / "summary.md").write_text("\n".join(summary_md) + "\n", encoding="utf-8")
    written.append(folder / "summary.md")
    header, rows = test_rows(results)
    written.append(_write_csv(folder / "tests.csv", header, rows))
    figures = plot_all(results, folder)
    written += figures
    claims = check_claims(results)
    title = "Different number of robots" if results.kind == "robots" else "Human laziness (door-opening probability)"
    lines = [f"# Experiment: {title}", "",
             "Paper §V-A. Each trial ran the real planner, restrictor and sim (with its human model) as separate processes over "
             "Zenoh in lockstep mode on a generated site. Rebuilt from `trials.csv` by `arroch experiment report`.", ""]
    lines += _section_trials(results)
    lines += ["## Figures", "", *[f"![{p.stem}]({p.name})" for p in figures], ""]
    lines += summary_md
    lines += _section_tests(results)
    lines += _section_claims(claims)
    lines += _section_drivers(results)
    lines += _section_params(results)
    lines += _section_time(results)
    lines += _section_discussion(results)
    (folder / "REPORT.md").write_text("\n".join(lines).rstrip() + "\n", encoding="utf-8")
    written.append(folder / "REPORT.md")
    log.info("report written to %s", folder / "REPORT.md")
    return written


def claims_of(folder: Path) -> list[dict[str, Any]]:
    """The claims' verdicts as plain data (for scripts and tests)."""
    return [{"title": c.title, "verdict": c.verdict, "detail": c.detail} for c in check_claims(load_results(folder))]
