"""``arroch study report DIR``: analyse a study's trials per participant and condition.

Measures of each trial (the simulator's metrics.json for times, her log.jsonl for what she did):

- ``team_time``: the team's completion time, the slowest agent's (metrics ``team_completion_time``;
  missing when the mission did not finish);
- ``human_time``: her completion time (metrics ``agent_completion_times.human``);
- ``robots_time``: the robots' completion times summed (the paper's y axis);
- ``agents_time``: every agent's completion time summed, hers included (the paper's test);
- ``door_openings`` (metrics ``human_door_openings``, else her ``open_door`` trips in the log),
  ``declarations`` (her a2(N), log) and ``time_away`` (s away from the puzzle before her task was
  done, log; see :mod:`.timeline`);
- the questionnaires: ``Q1``-``Q5`` (arroch-q) and, when asked, each NASA-TLX scale (``tlx_<name>``)
  and the raw TLX (``tlx_raw``, their mean).

Paired tests (:mod:`.stats`) compare every pair of conditions (in the plan's order, ``d = first -
second``) over the participants with a value in both; only complete trials count. Families, each
corrected with Holm across its measures and condition pairs: the Likert items; the times
(team, human, robots, agents); her behaviour (door openings, declarations, time away); NASA-TLX.

Written to ``--out`` (default ``DIR/report``): ``REPORT.md``, ``data.csv`` (tidy: one row per
participant x trial x measure), ``tests.json``, and the figures (:mod:`.figures`).
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .layout import StudyError, StudyFolder, StudyPlan
from .trialdata import LIKERT_ITEMS, TrialData, load_trials

if TYPE_CHECKING:
    from .stats import PairedResult

# scipy and matplotlib are imported when a report is made, not whenever `arroch study` starts.

TIME_MEASURES = {
    "team_time": "team completion time (s)",
    "human_time": "human completion time (s)",
    "robots_time": "robots' summed completion times (s)",
    "agents_time": "all agents' summed completion times (s)",
}
BEHAVIOUR_MEASURES = {
    "door_openings": "door openings by her",
    "declarations": "declarations a2(N)",
    "time_away": "time away from the puzzle (s)",
}
LIKERT_TEXT = {  # the paper's wording (real-world section)
    "Q1": "The tasks were easy to understand",
    "Q2": "It was easy to keep track of robot status",
    "Q3": "I could focus on my task with minimal distraction from robot",
    "Q4": "The task was not mentally demanding",
    "Q5": "I enjoyed working with the robot and would like to use such a system in the future",
}
FIGURES = {
    "times": "times_scatter.png",
    "team": "team_time_hist.png",
    "likert": "likert_means.png",
}


# ---------------------------------------------------------------------------- measures


def trial_measures(trial: TrialData) -> dict[str, float]:
    """Every measure this trial has a value for."""
    out: dict[str, float] = {}
    m = trial.metrics
    if m is not None:
        agents = m["agent_completion_times"]
        if m.get("team_completion_time") is not None:
            out["team_time"] = float(m["team_completion_time"])
        human = agents.get("human")
        robots = [v for k, v in agents.items() if k != "human"]
        if human is not None:
            out["human_time"] = float(human)
        if robots and all(v is not None for v in robots):
            out["robots_time"] = float(sum(robots))
            if human is not None:
                out["agents_time"] = float(human + sum(robots))
        if isinstance(m.get("human_door_openings"), int):
            out["door_openings"] = float(m["human_door_openings"])
    if trial.has_log:
        tl = trial.timeline()
        out.setdefault("door_openings", float(sum(1 for t in tl.trips if t.opened)))
        out["declarations"] = float(len(tl.declarations()))
        out["time_away"] = tl.time_away()
    for item, value in trial.answers.get("arroch-q", {}).items():
        out[item] = float(value)
    tlx = trial.answers.get("nasa-tlx", {})
    for scale, value in tlx.items():
        out[f"tlx_{scale}"] = float(value)
    if tlx:
        out["tlx_raw"] = sum(tlx.values()) / len(tlx)
    return out


def families(plan: StudyPlan, values: dict[str, dict[str, float]]) -> dict[str, list[str]]:
    """The test families and their measures, in report order (only measures someone has)."""
    seen = {k for v in values.values() for k in v}
    fams = {
        "likert": [q for q in LIKERT_ITEMS if q in seen] if "arroch-q" in plan.questionnaires else [],
        "times": [m for m in TIME_MEASURES if m in seen],
        "behaviour": [m for m in BEHAVIOUR_MEASURES if m in seen],
        "nasa-tlx": sorted(m for m in seen if m.startswith("tlx_")),
    }
    return {k: v for k, v in fams.items() if v}


@dataclass
class Analysis:
    plan: StudyPlan
    trials: list[TrialData]
    values: dict[str, dict[str, float]]  # trial id -> measure -> value
    tests: dict[str, list[PairedResult]]  # family -> results

    @property
    def complete(self) -> list[TrialData]:
        return [t for t in self.trials if t.complete]

    def by(self, measure: str, condition: str) -> list[float]:
        """The values of ``measure`` in the complete trials of ``condition``."""
        trials = [t for t in self.complete if t.condition == condition]
        return [self.values[t.trial][measure] for t in trials if measure in self.values[t.trial]]


def analyse(folder: StudyFolder) -> Analysis:
    from .stats import correct_family, paired

    plan = folder.plan()
    trials = load_trials(folder, plan)
    values = {t.trial: trial_measures(t) for t in trials}
    complete = [t for t in trials if t.complete]
    per: dict[tuple[str, str], TrialData] = {(t.participant, t.condition): t for t in complete}
    tests: dict[str, list[PairedResult]] = {}
    for family, measures in families(plan, {t.trial: values[t.trial] for t in complete}).items():
        results = []
        for measure in measures:
            for a, b in itertools.combinations(plan.conditions, 2):
                xs, ys = [], []
                for pid in plan.ids():
                    ta, tb = per.get((pid, a)), per.get((pid, b))
                    if ta and tb and measure in values[ta.trial] and measure in values[tb.trial]:
                        xs.append(values[ta.trial][measure])
                        ys.append(values[tb.trial][measure])
                results.append(paired(measure, family, a, b, xs, ys))
        tests[family] = correct_family(results)
    return Analysis(plan, trials, values, tests)


# ---------------------------------------------------------------------------- outputs


def _fmt(x: float | None) -> str:
    if x is None or math.isnan(x):
        return "n/a"
    if abs(x) >= 1000:
        return f"{x:.1f}"
    return f"{x:.4g}"


def _p(p: float) -> str:
    if math.isnan(p):
        return "n/a"
    return "< 0.0001" if p < 1e-4 else f"{p:.4f}"


def write_csv(analysis: Analysis, path: Path) -> int:
    """The tidy table: participant, trial, condition, order, status, measure, value. Returns its rows."""
    rows = 0
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["participant", "trial", "condition", "order", "status", "measure", "value"])
        for t in analysis.trials:
            for measure, value in analysis.values[t.trial].items():
                w.writerow([t.participant, t.trial, t.condition, t.order, t.status, measure, repr(round(value, 6))])
                rows += 1
    return rows


def write_figures(analysis: Analysis, out: Path) -> dict[str, Path]:
    from . import figures
    from .stats import mean_ci

    conds = analysis.plan.conditions
    points = {}
    for c in conds:
        pts = []
        for t in analysis.complete:
            v = analysis.values[t.trial]
            if t.condition == c and "human_time" in v and "robots_time" in v:
                pts.append((v["human_time"], v["robots_time"]))
        points[c] = pts
    paths = {k: out / name for k, name in FIGURES.items()}
    figures.times_scatter(points, paths["times"])
    figures.team_histogram({c: analysis.by("team_time", c) for c in conds}, paths["team"])
    if "arroch-q" in analysis.plan.questionnaires:
        means = {q: {c: mean_ci(analysis.by(q, c)) for c in conds if analysis.by(q, c)} for q in LIKERT_ITEMS}
        figures.likert_means(means, paths["likert"])
    else:
        del paths["likert"]
    return paths


def tests_json(analysis: Analysis) -> dict[str, Any]:
    return {
        "study": analysis.plan.name,
        "conditions": analysis.plan.conditions,
        "participants": len(analysis.plan.participants),
        "complete_trials": len(analysis.complete),
        "left_out": [
            {"trial": t.trial, "participant": t.participant, "status": t.status, "reason": t.reason}
            for t in analysis.trials
            if not t.complete
        ],
        "alpha": 0.05,
        "families": {fam: [r.as_dict() for r in results] for fam, results in analysis.tests.items()},
    }


def _label(measure: str) -> str:
    return (
        TIME_MEASURES.get(measure)
        or BEHAVIOUR_MEASURES.get(measure)
        or (f"{measure}: {LIKERT_TEXT[measure]}" if measure in LIKERT_TEXT else measure)
    )


def report_markdown(analysis: Analysis, figure_paths: dict[str, Path], out: Path) -> str:
    from .stats import mean_ci

    plan = analysis.plan
    conds = plan.conditions
    complete = analysis.complete
    lines = [
        f"# Study report: {plan.name}",
        "",
        f"Plan: {len(plan.participants)} participants x {len(conds)} conditions ({', '.join(conds)}), "
        f"{plan.design}, seed {plan.seed}, world {plan.world.kind}.",
        f"Trials: {len(analysis.trials)} planned, {len(complete)} complete and analysed.",
        "",
        "## Trials left out",
        "",
    ]
    left = [t for t in analysis.trials if not t.complete]
    if left:
        lines += ["| trial | status | why |", "|---|---|---|"]
        lines += [f"| {t.trial} | {t.status} | {t.reason} |" for t in left]
        lines.append("")
        lines.append("A participant whose trial in a condition is left out is left out of that pair's tests.")
    else:
        lines.append("None: every planned trial is complete.")
    noted = [t for t in complete if t.notes]
    lines += ["", "## Missing values in complete trials", ""]
    if noted:
        lines += [f"- {t.trial}: {'; '.join(t.notes)}" for t in noted]
        lines.append("")
        lines.append("A missing value leaves that participant out of the tests of that measure only.")
    else:
        lines.append("None.")

    lines += ["", "## Per condition", "", "| measure | " + " | ".join(conds) + " |", "|---|" + "---|" * len(conds)]
    for fam_measures in families(plan, {t.trial: analysis.values[t.trial] for t in complete}).values():
        for measure in fam_measures:
            cells = []
            for c in conds:
                vs = analysis.by(measure, c)
                est = mean_ci(vs)
                sd = (sum((v - est.value) ** 2 for v in vs) / (len(vs) - 1)) ** 0.5 if len(vs) > 1 else float("nan")
                cells.append(f"{_fmt(est.value)} ± {_fmt(sd)} (n={est.n})" if vs else "n/a")
            lines.append(f"| {measure} | " + " | ".join(cells) + " |")
    lines += ["", "Mean ± standard deviation (n trials).", ""]

    lines += ["## Paired tests", ""]
    lines += [
        "Wilcoxon signed-rank, two-sided, zero differences dropped, exact p given the mid-ranks; paired t "
        "beside it. Differences are first condition minus second; HL is the Hodges-Lehmann estimate. Holm "
        "corrects each family across its measures and condition pairs; the decision follows the corrected p "
        "at α = 0.05.",
        "",
    ]
    for family, results in analysis.tests.items():
        lines += [
            f"### {family}",
            "",
            "| measure | pair | n | median diff | HL | W | p | p (Holm) | t | p (t) | decision |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in results:
            lines.append(
                f"| {_label(r.measure)} | {r.a} − {r.b} | {r.n} | {_fmt(r.median_diff)} | {_fmt(r.hodges_lehmann)} | "
                f"{_fmt(r.wilcoxon.w)} | {_p(r.wilcoxon.p)} | {_p(r.p_holm)} | {_fmt(r.t)} | {_p(r.t_p)} | "
                f"{r.decision} |"
            )
        lines.append("")

    lines += ["## Figures", ""]
    captions = {
        "times": "Human completion time against the robots' summed completion times, per trial; ellipses: "
        "each condition's 2-D standard deviation (drawn for 3 trials or more).",
        "team": "Team completion time (the slowest agent) per condition; missions that did not finish are absent.",
        "likert": "Questionnaire means per item and condition with 95 % t intervals.",
    }
    for key, path in figure_paths.items():
        lines += [f"![{captions[key]}]({path.relative_to(out)})", "", captions[key], ""]

    lines += ["## Per participant", ""]
    candidates = [*TIME_MEASURES, *BEHAVIOUR_MEASURES, *LIKERT_ITEMS]
    shown = [m for m in candidates if any(m in v for v in analysis.values.values())]
    lines += [
        "| trial | condition | order | status | " + " | ".join(shown) + " |",
        "|---|---|---|---|" + "---|" * len(shown),
    ]
    for t in analysis.trials:
        v = analysis.values[t.trial]
        lines.append(
            f"| {t.trial} | {t.condition} | {t.order} | {t.status} | "
            + " | ".join(_fmt(v.get(m)) for m in shown)
            + " |"
        )
    lines += ["", "Times in site seconds. data.csv holds every value; tests.json every test.", ""]
    return "\n".join(lines)


def build_report(folder: StudyFolder, out: Path) -> Analysis:
    analysis = analyse(folder)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(analysis, out / "data.csv")
    figure_paths = write_figures(analysis, out)
    (out / "tests.json").write_text(json.dumps(tests_json(analysis), indent=2, ensure_ascii=False) + "\n")
    (out / "REPORT.md").write_text(report_markdown(analysis, figure_paths, out), encoding="utf-8")
    return analysis


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dir", metavar="DIR", help="the study folder")
    parser.add_argument("--out", metavar="DIR", help="where to write the report (default DIR/report)")


def summary_lines(analysis: Analysis) -> Sequence[str]:
    out = [f"{len(analysis.complete)} of {len(analysis.trials)} trials complete"]
    for results in analysis.tests.values():
        for r in results:
            out.append(f"  {r.measure:<14} {r.a} − {r.b}: n={r.n}, p(Holm)={_p(r.p_holm)}: {r.decision}")
    return out


def main(args: argparse.Namespace) -> int:
    folder = StudyFolder(args.dir)
    out = Path(args.out) if args.out else folder.report_dir
    try:
        analysis = build_report(folder, out)
    except StudyError as exc:
        print(f"arroch study report: {exc}", file=sys.stderr)
        return 2
    print("\n".join(summary_lines(analysis)))
    print(f"report written to {out / 'REPORT.md'}")
    return 0
