"""``arroch experiment report DIR``: everything a results folder says, rebuilt from its CSV.

Writes into DIR:

- ``summary.csv`` / ``summary.md``: per condition, the trials by status, the share of trials in
  which the human was the slowest agent, and the mean with its 95 % confidence interval of every
  figure (completed trials only);
- ``tests.csv``: ARROCH against each baseline per level, paired trial by trial, for the metrics of
  :data:`.comparisons.TESTED` (team completion time, sum of times, door openings, the human's
  time away): mean difference with its t interval, paired t, Wilcoxon signed-rank, the sign-flip
  permutation test (counts), d_z, TOST equivalence, Holm-adjusted p-values, the deciding test's
  estimate and interval at its Holm level, and the verdict;
- the figures: bars (:mod:`.plots`) for the robots and laziness sweeps, heatmaps (:mod:`.maps`)
  for the map;
- ``REPORT.md``: the sweep's parameters and the human model's (``params.json``), the design, the
  above, the paper's claims checked (:mod:`.claims`), the map's reading, how feedback changed the
  plans (point sweeps), the mixed model (population), what drives team completion time, the wall
  time of the sweep and where it went (``timing.csv``, ``runs.json``), and ``discussion.md``
  (written by a person, if present).

Only the CSV is needed; the side files add their sections when present.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import statistics
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from .claims import Claim, check_claims
from .comparisons import ALPHA, TESTED, Test, families, format_p_value, interval_label, level_text
from .design import format_p
from .params import varied_paths, write_params
from .record import key_of
from .results import COUNTS, METRICS, Level, ReportError, Results, TrialResult, load_results, statuses
from .stats import EXACT_FLIPS_MAX, PERMUTATION_RESAMPLES, PERMUTATION_SEED, Summary, summarize
from .store import JsonlStore

log = logging.getLogger("arroch.experiment")

EFFICIENCY_COLUMNS = (
    ("team_completion_time", "team completion (s)"),
    ("sum_of_times", "sum of times (s)"),
    ("slowest_robot_time", "slowest robot (s)"),
    ("human_completion_time", "human done (s)"),
)
HUMAN_COLUMNS = (
    ("door_openings", "door openings"),
    ("human_time_away", "time away (s)"),
    ("human_interruptions", "interruptions"),
    ("human_time_lost", "time lost (s)"),
    ("focus_declared", "focus declared"),
    ("feedback_sent", "feedback sent"),
    ("feedback_accepted", "feedback accepted"),
    ("replans", "replans"),
)
STATUSES = ("ok", "unfinished", "timeout", "error")
TITLES = {
    "robots": "Different number of robots",
    "laziness": "Human laziness (door-opening probability)",
    "map": "Map of where feedback pays (task length × interruption cost)",
    "detour": "A task the planner can reorder (only some deliveries behind her door)",
    "sensitivity": "Sensitivity analysis (one stage)",
    "population": "A population of simulated people",
}
MAX_POINTS_SHOWN = 60  # a sweep's points table in REPORT.md; beyond, trials.csv has them
PLAN_COLUMNS = (
    ("constraint_replans", "constraint replans"),
    ("plans_changed", "plans changed"),
    ("deliveries_reordered", "robots reordered"),
    ("door_wait_time", "wait at her door (s)"),
    ("robot_wait_time", "wait at any door (s)"),
)

__all__ = ["ReportError", "build_report", "claims_of", "summary_rows", "test_rows"]


# ---------------------------------------------------------------------------- formatting


def _num(value: float | None, digits: int = 3) -> str:
    return "" if value is None or math.isnan(value) else f"{value:.{digits}f}"


def _g(value: float) -> str:
    """A statistic in a CSV cell: six significant digits, empty when undefined."""
    return "" if math.isnan(value) else f"{value:.6g}"


def _value(value: Any) -> str:
    """A parameter's value for people: numbers compactly, anything else (e.g. ``faithful``) as text."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return ", ".join(_value(v) for v in value) if isinstance(value, (list, tuple)) else str(value)
    return str(value) if isinstance(value, int) else format_p(value)


def _mean_ci(s: Summary, digits: int = 1) -> str:
    if s.n == 0:
        return "–"
    if math.isnan(s.ci_low):
        return f"{s.mean:.{digits}f}"
    return f"{s.mean:.{digits}f} [{s.ci_low:.{digits}f}, {s.ci_high:.{digits}f}]"


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


def _slowest(trials: list[TrialResult]) -> tuple[int, int]:
    """(trials in which the human was the slowest agent, completed trials where that is known)."""
    known = [t.human_slowest for t in trials if t.ok and t.human_slowest is not None]
    return sum(known), len(known)


def _share(k: int, n: int) -> str:
    return f"{k}/{n} ({100 * k / n:.0f} %)" if n else "–"


# ---------------------------------------------------------------------------- tables


def _point_columns(results: Results) -> list[int]:
    """Which of a point sweep's level columns summary.csv adds (those it has no column for yet)."""
    if not results.points:
        return []
    keyed = ("door_probability", "task_mean", "interruption_cost")
    return [i for i, name in enumerate(results.level_columns) if name not in keyed]


def summary_rows(results: Results) -> tuple[list[str], list[list[str]]]:
    extra = _point_columns(results)
    header = [
        "method",
        "robots",
        "objects",
        "door_probability",
        "task_mean",
        "interruption_cost",
        *(results.level_columns[i] for i in extra),
        "trials",
        *STATUSES,
        "human_slowest",
        "human_slowest_share",
    ]
    for metric in METRICS:
        header += [f"{metric}_mean", f"{metric}_ci_low", f"{metric}_ci_high", f"{metric}_n"]
    rows = []
    for level, method, trials in results.conditions():
        counts = statuses(trials)
        first = trials[0]
        slow, known = _slowest(trials)
        row = [
            method,
            str(first.robots),
            str(first.objects),
            format_p(first.p),
            format_p(first.task),
            format_p(first.cost),
            *(results.level_cells(level)[i] for i in extra),
            str(len(trials)),
            *(str(counts.get(s, 0)) for s in STATUSES),
            str(slow),
            _num(slow / known if known else None),
        ]
        for metric in METRICS:
            s = summarize(results.values(method, level, metric))
            row += [_num(s.mean), _num(s.ci_low), _num(s.ci_high), str(s.n)]
        rows.append(row)
    return header, rows


def test_rows(results: Results, tested: dict[str, list[Test]] | None = None) -> tuple[list[str], list[list[str]]]:
    """``tests.csv``: one row per (metric, level, baseline) with complete pairs."""
    tested = tested if tested is not None else families(results)
    header = [
        "metric",
        *results.level_columns,
        "baseline",
        "n_pairs",
        "n_nonzero",
        "mean_arroch",
        "mean_baseline",
        "mean_diff",
        "t_ci_low",
        "t_ci_high",
        "sd_diff",
        "paired_t",
        "paired_t_p",
        "wilcoxon_w",
        "wilcoxon_p",
        "perm_p",
        "primary_test",
        "primary_p",
        "primary_p_holm",
        "tost_margin",
        "tost_p",
        "tost_p_holm",
        "d_z",
        "estimate",
        "interval_low",
        "interval_high",
        "interval_level",
        "interval_kind",
        "verdict",
    ]
    rows = []
    for metric in TESTED:
        for t in tested.get(metric.name, []):
            r = t.result
            if r.n < 2:
                continue
            rows.append(
                [
                    metric.name,
                    *results.level_cells(t.level),
                    t.baseline,
                    str(r.n),
                    str(r.n_nonzero),
                    _num(r.mean_a),
                    _num(r.mean_b),
                    _num(r.mean_diff),
                    _num(r.ci_low),
                    _num(r.ci_high),
                    _num(r.sd_diff),
                    _g(r.t),
                    _g(r.t_p),
                    _g(r.wilcoxon.w),
                    _g(r.wilcoxon.p),
                    _g(r.perm_p),
                    metric.primary_test,
                    _g(t.primary_p),
                    _g(t.primary_p_holm),
                    f"{metric.margin:g}",
                    _g(r.tost_p),
                    _g(t.tost_p_holm),
                    _g(r.d_z),
                    *_interval_cells(t),
                    t.verdict,
                ]
            )
    return header, rows


def _interval_cells(t: Test) -> list[str]:
    i = t.interval
    if i is None:
        return ["", "", "", "", ""]
    return [_num(i.estimate), _num(i.low), _num(i.high), _g(i.level), i.kind]


# ---------------------------------------------------------------------------- sections


def _section_design() -> list[str]:
    margins = ", ".join(f"{m.label} ±{m.margin:g}{m.suffix}" for m in TESTED)
    resamples = f"{PERMUTATION_RESAMPLES:_}".replace("_", " ")
    return [
        "## Design",
        "",
        "Paired trials (common random numbers): for one trial index every method meets the same site and the same "
        "human "
        "draws (task time, focus intervals, each decision), so methods are compared trial by trial on the differences "
        "ARROCH − baseline; a trial that did not complete in one method drops that pair. Per level and baseline: the "
        "mean "
        "difference with its 95 % t interval, the paired t-test, the Wilcoxon signed-rank test (zero differences "
        "dropped; "
        "exact for small samples) — the primary test for times — and for counts a sign-flip permutation test on the "
        f"differences (exact up to {EXACT_FLIPS_MAX} nonzero differences, otherwise {resamples} random flips "
        f"with the fixed seed {PERMUTATION_SEED}) — the primary test for counts; d_z = mean / sd of the differences "
        "(n/a "
        f"without spread); equivalence by two one-sided paired t-tests (TOST) against the margins {margins} (chosen "
        "before "
        "the runs: 30 s is 5 % of the 600 s task and half the sd of her task draw; 10 s is about one door trip; half "
        "an "
        "opening is less than one door per trial). Holm's correction over each metric's family (all levels × "
        "baselines), "
        "separately for the primary and the TOST p-values; every verdict uses the Holm-adjusted values at α = "
        f"{ALPHA:g}. "
        "Each table's interval is the deciding test's at the level Holm tested it at: the Hodges–Lehmann estimate "
        "with its Wilcoxon interval (times), the mean difference with its sign-flip interval (counts); the paired t "
        "interval is in tests.csv only. "
        "Conventions in detail: `services/experiments/stats.py` and `comparisons.py`.",
        "",
    ]


def _section_sweep(results: Results) -> list[str]:
    spec = results.spec
    lines = ["## Sweep", ""]
    if spec is None:
        return lines + ["No sweep.json in this folder: the conditions are those trials.csv shows.", ""]
    per_point = {name for point in spec.points for name in point}

    def keyed(name: str, values: tuple[float, ...]) -> str:
        return "set per point (below, or trials.csv)" if name in per_point else _value(values)

    rows = [
        ["kind", spec.kind],
        ["methods", _value(spec.methods)],
        ["robots", _value(spec.robots)],
        ["objects per robot", str(spec.objects)],
        ["door-opening probabilities", keyed("door_probability", spec.ps)],
        ["mean task lengths (s)", keyed("task_mean", spec.tasks)],
        ["interruption costs (s)", keyed("interruption_cost", spec.costs)],
        ["trials per condition", str(spec.trials)],
        ["base seed", str(spec.seed)],
        ["buildings", "detour (only some deliveries behind her door)" if spec.domain == "detour" else "the paper's"],
        ["time limit (sim s)", "the simulator's default" if spec.time_limit is None else _value(spec.time_limit)],
        [
            "human model",
            "the simulator's defaults" if spec.human_config is None else "a custom --human-config (text in sweep.json)",
        ],
    ]
    rows += [[name, _value(value)] for name, value in sorted(spec.extra.items())]
    rows += [[f"human: {name}", _value(value)] for name, value in sorted(spec.human.items())]
    lines += _table(["parameter", "value"], rows) + [""]
    if spec.points and len(spec.points) <= MAX_POINTS_SHOWN:
        names = sorted({n for p in spec.points for n in p})
        lines += _table(
            ["point", *names], [[str(i), *(_value(p.get(n, "")) for n in names)] for i, p in enumerate(spec.points)]
        )
        lines += [""]
    return lines


def _section_params(results: Results) -> list[str]:
    params = results.params
    if not params:
        return ["## Human model", "", "No params.json in this folder (it is written when a sweep completes).", ""]
    human = params.get("human", {})
    varied = params.get("varied_per_trial", {})
    lines = [
        "## Human model (as the simulator reported it)",
        "",
        f"Source: {params.get('source', 'params.json')}."
        + (
            " Varied per trial: " + "; ".join(f"{k} ∈ {{{_value(vs)}}}" for k, vs in varied.items()) + "."
            if varied
            else ""
        ),
        "",
    ]
    lines += _table(["option", "value"], [[k, _value(v)] for k, v in sorted(human.items())])
    for name in ("site_params", "engine", "robot_motion"):
        if params.get(name):
            lines += ["", f"{name}: " + ", ".join(f"{k} = {_value(v)}" for k, v in sorted(params[name].items()))]
    if params.get("mode") is not None:
        lines += ["", f"clock mode: {params.get('mode')}"]
    if params.get("differs"):
        lines += [
            "",
            "**Parameters that differ between trials** (the trials are not comparable on these): "
            + "; ".join(f"{k}: {_value(v)}" for k, v in params["differs"].items()),
        ]
    return lines + [""]


def _section_trials(results: Results) -> list[str]:
    counts = statuses(results.trials)
    lines = [
        "## Trials",
        "",
        f"{len(results.trials)} trials: " + ", ".join(f"{counts.get(s, 0)} {s}" for s in STATUSES) + ". "
        "Statistics use the completed (`ok`) trials only; the paired tests, the pairs in which both methods completed.",
    ]
    codes: dict[str, int] = {}
    for r in results.timing:
        if r.get("code"):
            codes[r["code"]] = codes.get(r["code"], 0) + 1
    if len(codes) == 1:
        lines += [
            "",
            f"Every trial ran on the same services' code (fingerprint `{next(iter(codes))}`, see timing.csv).",
        ]
    elif codes:
        lines += [
            "",
            f"**The trials ran on {len(codes)} versions of the services' code** (the sources changed during the sweep, "
            "or trials were run again on later code with `--rerun`; fingerprint: trials): "
            + ", ".join(f"`{c}`: {n}" for c, n in codes.items())
            + ". Trials of different versions compare only as far as the change between them leaves them alone "
            "(the reading should say how far).",
        ]
    failed = [t for t in results.trials if not t.ok]
    if failed:
        lines += ["", "Trials that did not complete (first 10):", ""]
        lines += [
            f"- {t.method}, {results.level_label(results.level_of(t))}, trial {t.trial}: {t.status} — {t.reason}"
            for t in failed[:10]
        ]
    return lines + [""]


def _summary_table(results: Results, columns: tuple[tuple[str, str], ...], slowest: bool) -> list[str]:
    head = [*results.level_columns, "method", "ok / n", *(label for _, label in columns)] + (
        ["human slowest"] if slowest else []
    )
    rows = []
    for level, method, trials in results.conditions():
        row = [*results.level_cells(level), method, f"{sum(t.ok for t in trials)} / {len(trials)}"]
        for metric, _ in columns:
            row.append(_mean_ci(summarize(results.values(method, level, metric)), 2 if metric in COUNTS else 1))
        if slowest:
            row.append(_share(*_slowest(trials)))
        rows.append(row)
    return _table(head, rows)


def _section_summary(results: Results) -> list[str]:
    return [
        "## Summary (mean [95 % CI])",
        "",
        "### Team efficiency",
        "",
        *_summary_table(results, EFFICIENCY_COLUMNS, slowest=True),
        "",
        "*sum of times*: every agent's completion time added up (the paper's real-world measure); *human slowest*: "
        "completed trials in which the human's own task ended last, i.e. set the team's time.",
        "",
        "### The human's workload and the communication",
        "",
        *_summary_table(results, HUMAN_COLUMNS, slowest=False),
        "",
        "*time away*: walking to doors and opening them; *interruptions*: walks to a door begun during one of her "
        "focus "
        "intervals; *time lost*: her task time lost to them (the interruption cost each).",
        "",
    ]


def _section_tests(results: Results, tested: dict[str, list[Test]]) -> list[str]:
    if not any(t.result.n >= 2 for tests in tested.values() for t in tests):
        return [
            "## ARROCH against each baseline (paired)",
            "",
            "Not available: the sweep needs ARROCH, a baseline and two complete pairs per level.",
            "",
        ]
    out = [
        "## ARROCH against each baseline (paired)",
        "",
        "Δ = ARROCH − baseline over the pairs (negative: ARROCH lower). Holm: over all levels and baselines of one "
        "metric. The verdict reads the Holm-adjusted p-values only (Design). The interval is the deciding test's, at "
        "the level Holm tested it at (given beside it): the Hodges–Lehmann estimate with its Wilcoxon interval for "
        "times, the mean with its sign-flip interval for counts; it excludes 0 where the verdict is significant.",
        "",
    ]
    for metric in TESTED:
        rows = []
        for t in tested.get(metric.name, []):
            r, d = t.result, metric.digits
            if r.n < 2:
                continue
            rows.append(
                [
                    *results.level_cells(t.level),
                    t.baseline,
                    str(r.n),
                    f"{r.mean_a:.{d}f} vs {r.mean_b:.{d}f}",
                    t.interval_text() + level_text(t),
                    "n/a" if math.isnan(r.t) else f"{r.t:.2f} ({format_p_value(r.t_p)})",
                    f"{r.wilcoxon.w:g} ({format_p_value(r.wilcoxon.p)})",
                    *([format_p_value(r.perm_p)] if metric.count else []),
                    format_p_value(t.primary_p_holm),
                    format_p_value(t.tost_p_holm),
                    "n/a" if math.isnan(r.d_z) else f"{r.d_z:.2f}",
                    t.verdict,
                ]
            )
        head = [
            *results.level_columns,
            "baseline",
            "pairs",
            "mean ARROCH vs baseline",
            interval_label(metric),
            "paired t (p)",
            "Wilcoxon W (p)",
            *(["permutation p"] if metric.count else []),
            f"{metric.primary_test} Holm p",
            f"TOST ±{metric.margin:g} Holm p",
            "d_z",
            "verdict",
        ]
        out += [f"### {metric.label}" + (f" ({metric.unit})" if metric.unit else ""), "", *_table(head, rows), ""]
    return out


def _section_plans(results: Results) -> list[str]:
    """How feedback changed the plans (point sweeps: ``plan_changes`` of the trials, :mod:`.plan_changes`)."""
    rows = []
    for level, method, trials in results.conditions():
        row = [*results.level_cells(level), method]
        for metric, _ in PLAN_COLUMNS:
            row.append(_mean_ci(summarize(results.values(method, level, metric)), 2 if metric in COUNTS else 1))
        ok = [t for t in trials if t.ok]
        changed = sum(1 for t in ok if (t.values.get("plans_changed") or 0) > 0)
        rows.append([*row, _share(changed, len(ok))])
    head = [*results.level_columns, "method", *(label for _, label in PLAN_COLUMNS), "trials with a plan changed"]
    return [
        "## How feedback changed the plans",
        "",
        "Per trial (mean [95 % CI] over completed trials): *constraint replans*, plans that answered an accepted "
        "a2(N) at the world version it came in; *plans changed*, those in which some robot's actions (not only their "
        "times) differ from the plan they replaced; *robots reordered*, robots whose order of the deliveries still "
        "to make changed in one of them (summed); the robots' time waiting at her door for it to open, and at any "
        "door (`services/experiments/plan_changes.py`). Without feedback (no-feedback, no-comm) the first three are 0.",
        "",
        *_table(head, rows),
        "",
    ]


def _section_mixed(results: Results) -> list[str]:
    """The population's mixed model beside the paired tests (:mod:`.mixed`)."""
    from .mixed import Observation, fit_mixed

    lines = [
        "## Mixed-effects model (method fixed, person random)",
        "",
        "y = β_method + u_person + ε, fitted by REML (statsmodels MixedLM, a random intercept per simulated person); "
        "ARROCH − baseline with its 95 % Wald interval. Beside the paired tests above, which pool every person's "
        "pairs. Person sd: how much people differ; residual sd: how much one person's missions do.",
        "",
    ]
    rows = []
    for metric in ("team_completion_time", "sum_of_times", "door_openings", "human_time_away"):
        observations = [
            Observation(t.point, t.method, t.values[metric])  # type: ignore[arg-type]
            for t in results.trials
            if t.ok and t.values.get(metric) is not None
        ]
        fit = fit_mixed(metric, observations)
        if not fit.effects:
            rows.append([metric, "–", "–", "–", "–", "–", fit.note or "not fitted"])
            continue
        for e in fit.effects:
            rows.append(
                [
                    metric,
                    e.baseline,
                    f"{e.estimate:+.2f} [{e.low:+.2f}, {e.high:+.2f}]",
                    format_p_value(e.p),
                    f"{fit.person_sd:.2f}",
                    f"{fit.residual_sd:.2f}",
                    f"{fit.persons} persons, {fit.observations} missions" + (f"; {fit.note}" if fit.note else ""),
                ]
            )
    head = ["metric", "baseline", "ARROCH − baseline [95 %]", "p", "person sd", "residual sd", "data"]
    priors = (results.spec.extra.get("priors") if results.spec else None) or []
    return (
        lines + _table(head, rows) + [""] + (["Persons drawn from: " + "; ".join(priors) + ".", ""] if priors else [])
    )


def _section_claims(claims: list[Claim]) -> list[str]:
    out = [
        "## The paper's claims",
        "",
        "Each (level, baseline) is *lower (significant)* when the primary test's Holm-adjusted p < 0.05 and ARROCH's "
        "mean difference is negative; *higher (significant)* likewise with a positive one (with *within ±margin* "
        "added when TOST also puts it inside the equivalence margin); *equivalent* when only the Holm-adjusted TOST "
        "p < 0.05; otherwise *not significant*. A claim is *confirmed* when every comparison supports it; "
        "*contradicted* when any Holm-significant comparison goes against it; *equivalent* when every comparison is "
        "inside the margin (TOST); *partly* otherwise when some comparison supports it; *not confirmed* when none "
        "supports it and none goes against it.",
        "",
    ]
    for claim in claims:
        out += [f"### {claim.title}: **{claim.verdict}**", "", f"Claim: {claim.statement}", "", claim.detail, ""]
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

        def mean(metric: str, mine: list = mine) -> str:  # this method's trials, bound now
            return _mean_ci(summarize([t.values[metric] for t in mine if t.values.get(metric) is not None]))

        lines.append(
            f"- {method}: the human was the slowest agent in {_share(*_slowest(mine))} of the completed trials; her "
            f"task ended at {mean('human_completion_time')} s on average (her task needed {mean('human_task_time')} s "
            f"of work), the last robot's delivery at {mean('slowest_robot_time')} s; the sum of all agents' times was "
            f"{mean('sum_of_times')} s; she spent {mean('human_time_away')} s away from her task on doors and lost "
            f"{mean('human_time_lost')} s to {mean('human_interruptions')} interruptions."
        )
    return lines + [""]


def _section_contacts(results: Results) -> list[str]:
    """How often robots met each other and the walls, as the simulator counted it
    (services/sim/overlaps.py, services/sim/walls.py)."""
    rows = []
    for level, method, _trials in results.conditions():
        counts = results.values(method, level, "robot_overlaps")
        if counts:
            walls = results.values(method, level, "wall_contacts")
            deepest = results.values(method, level, "wall_depth_max")
            failed = results.values(method, level, "actions_failed")
            rows.append(
                [
                    *results.level_cells(level),
                    method,
                    f"{sum(c == 0 for c in counts)} / {len(counts)}",
                    _g(statistics.median(counts)),
                    _g(max(counts)),
                    _g(statistics.median(walls)) if walls else "",
                    _g(round(1000.0 * max(deepest))) if deepest else "",
                    f"{_g(statistics.median(failed))} / {_g(max(failed))}" if failed else "",
                ]
            )
    if not rows:
        return []
    columns = [
        "method",
        "trials with none",
        "median",
        "max",
        "wall contacts (median)",
        "deepest into a wall (mm)",
        "failed actions (median / max)",
    ]
    motion = (results.params or {}).get("robot_motion", {})
    tolerance = f"{_g(round(1000.0 * motion['wall_tolerance']))} mm" if "wall_tolerance" in motion else "its tolerance"
    give_up = f"{_g(motion['give_up'])} s" if "give_up" in motion else "for long"
    return [
        "## Contacts and failed actions",
        "",
        "Times two robots' discs began to intersect (by more than 1 mm) in a completed trial, as the simulator "
        "counted them (`robot_overlaps` in `trials.csv`); 0 is a mission without a collision. Beside them, times "
        "a robot's disc began to reach into a wall (`wall_contacts`; a robot grazing a doorway's jamb counts) and "
        f"the deepest any reached (`wall_depth_max`; the simulator's wall guard refuses steps past {tolerance}). "
        f"Robots never push through one another: a robot kept back {give_up} with no way around fails its action "
        "and the planner plans again, so those waits show as failed actions (`actions_failed`).",
        "",
        *_table([*results.level_columns, *columns], rows),
        "",
    ]


def _section_time(results: Results) -> list[str]:
    if not results.timing and not results.runs:
        return []
    lines = ["## Wall time", ""]
    if results.runs:
        total = sum(float(r.get("wall_time", 0.0)) for r in results.runs)
        lines.append(
            f"{len(results.runs)} session(s), {total / 60:.1f} min of wall time in all "
            + "("
            + "; ".join(
                f"{r.get('started', '?')}: {float(r.get('wall_time', 0)) / 60:.1f} min, {r.get('trials_run')} trials, "
                f"{r.get('jobs')} jobs, router per {r.get('router')}, {r.get('ended')}"
                for r in results.runs
            )
            + ")."
        )
        lines.append("")
    rows = [r for r in results.timing if r.get("wall_time")]
    if rows:
        versions = {t.key: t.values.get("world_versions") for t in results.trials}

        def mean(name: str, subset: list[dict[str, str]]) -> str:
            vals = [float(r[name]) for r in subset if r.get(name)]
            return f"{sum(vals) / len(vals):.2f}" if vals else "–"

        def per_version(subset: list[dict[str, str]]) -> str:
            """Mission wall time per world version: one lockstep round trip (sim → planner → sim)."""
            pairs = [
                (float(r["mission_wall_time"]), versions.get(key_of(r))) for r in subset if r.get("mission_wall_time")
            ]
            pairs = [(w, v) for w, v in pairs if v]
            return f"{1000 * sum(w for w, _ in pairs) / sum(v for _, v in pairs):.0f}" if pairs else "–"

        groups: dict[Level, list[dict[str, str]]] = {}
        for r in rows:
            groups.setdefault(results.level_of(key_of(r)), []).append(r)
        head = [
            *results.level_columns,
            "trials",
            "wall / trial (s)",
            "services up (s)",
            "sim start-up + end (s)",
            "mission (s)",
            "planner solve (s)",
            "plans",
            "ms per world version",
            "shutdown (s)",
            "sim s per wall s",
        ]
        table = [
            [
                *results.level_cells(level),
                str(len(g)),
                mean("wall_time", g),
                mean("services_up", g),
                mean("sim_startup", g),
                mean("mission_wall_time", g),
                mean("planner_solve_time", g),
                mean("plans", g),
                per_version(g),
                mean("shutdown", g),
                mean("realtime_factor", g),
            ]
            for level, g in groups.items()
        ]
        lines += [
            "Per trial, mean (from timing.csv; trials ran in parallel, so the sweep's wall time is about the sum / "
            "jobs). "
            "*ms per world version*: mission wall time over the world versions the planner had to answer, i.e. "
            "the cost of one lockstep round trip including the replan.",
            "",
            *_table(head, table),
            "",
        ]
    return lines


def _section_discussion(results: Results) -> list[str]:
    path = results.folder / "discussion.md"
    if not path.exists():
        return ["## Discussion", "", "No discussion.md in this folder yet.", ""]
    return ["## Discussion", "", path.read_text(encoding="utf-8").strip(), ""]


# ---------------------------------------------------------------------------- the whole report


def build_report(folder: Path) -> list[Path]:
    """Write every report file into ``folder``; returns their paths. A sensitivity analysis's folder
    (its two stages in ``morris/`` and ``sobol/``) gets its own report (:mod:`.sensitivity_report`)."""
    from .maps import map_section, plot_maps  # matplotlib only here
    from .plots import plot_all

    folder = Path(folder)
    if (folder / "morris" / "design.json").exists():
        from .sensitivity_report import build_sensitivity_report

        return build_sensitivity_report(folder)
    results = load_results(folder)
    written = []
    metrics = JsonlStore(folder / "metrics.jsonl")
    if metrics.path.exists():  # the model's parameters, from the same trials
        factors = results.spec.factor_names() if results.spec else ()
        write_params(folder / "params.json", (r["metrics"] for r in metrics.load()), varied_paths(factors))
        results.params = json.loads((folder / "params.json").read_text(encoding="utf-8"))
        written.append(folder / "params.json")
    tested = families(results)
    header, rows = summary_rows(results)
    written.append(_write_csv(folder / "summary.csv", header, rows))
    summary_md = _section_summary(results)
    (folder / "summary.md").write_text("\n".join(summary_md) + "\n", encoding="utf-8")
    written.append(folder / "summary.md")
    header, rows = test_rows(results, tested)
    written.append(_write_csv(folder / "tests.csv", header, rows))
    figures = plot_maps(results, tested, folder) if results.kind == "map" else plot_all(results, folder)
    written += figures
    claims = check_claims(results, tested)
    lines = [
        f"# Experiment: {TITLES.get(results.kind, results.kind)}",
        "",
        "Paper §V-A. Each trial ran the real planner, restrictor and sim (with its human model) as separate processes "
        "over "
        "Zenoh in lockstep mode on a generated site. Rebuilt from `trials.csv` by `arroch experiment report`.",
        "",
    ]
    lines += _section_sweep(results)
    lines += _section_params(results)
    lines += _section_design()
    lines += _section_trials(results)
    lines += ["## Figures", "", *[f"![{p.stem}]({p.name})" for p in figures], ""]
    lines += summary_md
    lines += _section_tests(results, tested)
    if results.kind == "map":
        lines += map_section(results, tested)
    if results.points:
        lines += _section_plans(results)
    if results.kind == "population":
        lines += _section_mixed(results)
    lines += _section_claims(claims)
    lines += _section_drivers(results)
    lines += _section_contacts(results)
    lines += _section_time(results)
    lines += _section_discussion(results)
    (folder / "REPORT.md").write_text("\n".join(lines).rstrip() + "\n", encoding="utf-8")
    written.append(folder / "REPORT.md")
    log.info("report written to %s", folder / "REPORT.md")
    return written


def claims_of(folder: Path) -> list[dict[str, Any]]:
    """The claims' verdicts as plain data (for scripts and tests)."""
    return [{"title": c.title, "verdict": c.verdict, "detail": c.detail} for c in check_claims(load_results(folder))]
