"""``arroch experiment sensitivity``: which parameters decide the sign and size of ARROCH's differences.

Two stages, each an ordinary point sweep (:mod:`.runner`) in a folder of its own:

1. **Morris screening** (``DIR/morris``): ``--trajectories`` one-at-a-time trajectories over every
   factor of :data:`SCREEN` on a ``--levels`` grid (SALib's ``morris.sample``); each point is run
   with all three methods ``--replicates`` times.
2. **Sobol indices** (``DIR/sobol``) on what matters: the ``--sobol-factors`` factors with the
   largest μ* (scaled by the largest of its output) over the four outputs, the others held at their
   nominal values; Saltelli's sample of ``--sobol-n`` base points (SALib's ``sobol.sample``, first
   and total order).

**Outputs** (per point: the mean over its replicates of the paired differences): ARROCH − No-feedback
and ARROCH − No-comm on team completion time and on the sum of all agents' times.

**Paired by common random numbers**: every point of both stages meets the same buildings and the
same human draws for replicate ``r`` (the seeds leave the point out, :mod:`.design`), so an
elementary effect (two neighbouring points of a trajectory) is measured on the same draws and the
noise of the draws does not enter it as noise, only through the interaction of the draws with the
factors. Within a point, the methods are paired as in every sweep.

**Reading** (``DIR/REPORT.md``, written from the two folders): per output, the mean difference over
the Morris points and the share of points where ARROCH is lower; per factor, Morris's μ (signed:
the direction), μ* (the size of its effect) with its bootstrap interval and σ (interactions and
non-linearity), the mean output at the factor's lower and upper half of its range (which way it
moves the sign); Sobol's first-order and total indices with their bootstrap intervals. Figures: a
μ*–σ plot per output (``morris_mu_star_sigma.png``) and the Sobol indices (``sobol_indices.png``).
A point whose trials did not complete in a method has no output: it takes the mean of the other
points (the analysis needs every point), and the report counts how many did.

The default design (3 trajectories × 12 points, 4 Sobol base points × 4 on 2 factors, 1 replicate,
2 robots × 3 objects in the detour domain: 108 + 48 trials) is a screening sized for about 30
minutes on 2 cores (estimated from trial times measured here under load, ~8, ~28 and ~41 s at
capacity 1, 2 and 3: 23 minutes for Morris, 3-10 for Sobol depending on whether capacity is
chosen); its Sobol indices carry wide intervals. Larger designs: ``--trajectories``,
``--sobol-n``, ``--replicates``, with ``--cluster``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .design import METHODS, SweepSpec
from .factors import factor
from .results import Results, load_results

log = logging.getLogger("arroch.experiment")

DESIGN_FILE = "design.json"  # a stage's SALib sample (its unrounded matrix, for the analysis)
SUMMARY_FILE = "sensitivity.json"  # the analysis, as data
STAGES = ("morris", "sobol")
SALIB_RESAMPLES = 1000  # bootstrap resamples of SALib's intervals


@dataclass(frozen=True)
class Range:
    """A screened factor: its range, its value when another stage holds it fixed, and why."""

    name: str
    low: float
    high: float
    nominal: float
    source: str


SCREEN = (
    Range(
        "interruption_cost", 0.0, 60.0, 0.0, "the map's range (0-60 s); 0 is the sim's default (the paper states none)"
    ),
    Range("focus_fraction", 0.1, 0.6, 0.6, "chosen; 0.6 is the default model's share at its 600 s task (2 x 3 min)"),
    Range("focus_count", 1, 4, 2, "chosen around the sim's default (2)"),
    Range("declare_time", 1.0, 10.0, 1.0, "1 s: one tap (the sim's default); 5 s the earlier value; 10 s chosen"),
    Range("decision_interval", 5.0, 30.0, 10.0, "chosen around the sim's default (10 s)"),
    Range("focus_responsiveness", 0.0, 1.0, 1.0, "0: the strict reading of an undeclared focus; 1: faithful"),
    Range("anticipation", 0.0, 60.0, 0.0, "chosen: off to one minute of a robot's planned approach"),
    Range("capacity", 1, 3, 1, "the issue's factor (1-3); 1 is the paper's robots"),
    Range("door_hold", 10.0, 40.0, 20.0, "chosen: half to twice the site default (20 s)"),
    Range("door_share", 0.2, 1.0, 0.5, "1: the paper's task (every delivery through her door); 0.5 the detour default"),
    Range("task_mean", 150.0, 900.0, 600.0, "the map's range; decides whether she or the robots finish last"),
)
OUTPUTS = (
    ("team_completion_time", "no-feedback"),
    ("team_completion_time", "no-comm"),
    ("sum_of_times", "no-feedback"),
    ("sum_of_times", "no-comm"),
)


# ---------------------------------------------------------------------------- designs


@dataclass(frozen=True)
class Design:
    """One stage's sample: the SALib problem and its unrounded matrix (a row per point)."""

    method: str  # morris or sobol
    names: list[str]
    bounds: list[list[float]]
    x: list[list[float]]
    fixed: dict[str, float]  # factors held at their nominal value
    levels: int = 4  # Morris grid levels

    @property
    def problem(self) -> dict[str, Any]:
        return {"num_vars": len(self.names), "names": list(self.names), "bounds": [list(b) for b in self.bounds]}

    def points(self) -> tuple[dict[str, float], ...]:
        """The sweep's points: each row's factors (integer factors rounded) and the fixed ones."""
        out = []
        for row in self.x:
            point = {name: factor(name).clip(float(v)) for name, v in zip(self.names, row, strict=True)}
            point.update(self.fixed)
            out.append({k: (int(v) if factor(k).integer else v) for k, v in sorted(point.items())})
        return tuple(out)

    def save(self, folder: Path) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / DESIGN_FILE).write_text(json.dumps(asdict(self), indent=1) + "\n", encoding="utf-8")

    @classmethod
    def load(cls, folder: Path) -> Design:
        return cls(**json.loads((folder / DESIGN_FILE).read_text(encoding="utf-8")))


def _ranges(names: list[str] | None) -> list[Range]:
    if not names:
        return list(SCREEN)
    known = {r.name: r for r in SCREEN}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"--factors: unknown {', '.join(unknown)} (screened: {', '.join(known)})")
    return [known[n] for n in names]


def morris_design(ranges: list[Range], trajectories: int, levels: int, seed: int) -> Design:
    from SALib.sample import morris

    design = Design("morris", [r.name for r in ranges], [[r.low, r.high] for r in ranges], [], {}, levels)
    x = morris.sample(design.problem, N=trajectories, num_levels=levels, seed=seed)
    return Design("morris", design.names, design.bounds, x.tolist(), {}, levels)


def sobol_design(ranges: list[Range], chosen: list[str], n: int, seed: int) -> Design:
    from SALib.sample import sobol

    varied = [r for r in ranges if r.name in chosen]
    fixed = {r.name: factor(r.name).clip(r.nominal) for r in ranges if r.name not in chosen}
    design = Design("sobol", [r.name for r in varied], [[r.low, r.high] for r in varied], [], fixed)
    x = sobol.sample(design.problem, n, calc_second_order=False, seed=seed)
    return Design("sobol", design.names, design.bounds, x.tolist(), fixed)


# ---------------------------------------------------------------------------- outputs and analysis


def outputs(results: Results, points: int) -> dict[tuple[str, str], np.ndarray]:
    """Per output, per point: the mean of ARROCH − baseline over its replicates (NaN without a pair)."""
    out = {}
    for metric, baseline in OUTPUTS:
        y = np.full(points, np.nan)
        for i in range(points):
            pairs = results.pairs(metric, i, "arroch", baseline)
            if pairs:
                y[i] = float(np.mean([p.a - p.b for p in pairs]))
        out[(metric, baseline)] = y
    return out


def _filled(y: np.ndarray) -> tuple[np.ndarray, int]:
    """``y`` with missing points at the mean of the others, and how many were missing."""
    missing = int(np.isnan(y).sum())
    if missing == len(y):
        return np.zeros_like(y), missing
    return np.where(np.isnan(y), float(np.nanmean(y)), y), missing


@dataclass
class FactorEffect:
    name: str
    mu: float = math.nan
    mu_star: float = math.nan
    mu_star_conf: float = math.nan
    sigma: float = math.nan
    low_half: float = math.nan  # mean output over points in the factor's lower half
    high_half: float = math.nan
    s1: float = math.nan
    s1_conf: float = math.nan
    st: float = math.nan
    st_conf: float = math.nan


@dataclass
class OutputAnalysis:
    metric: str
    baseline: str
    points: int
    missing: int
    mean: float  # over the points
    lower_share: float  # share of points where ARROCH is lower
    effects: list[FactorEffect]


def _halves(design: Design, y: np.ndarray, name: str) -> tuple[float, float]:
    column = np.array([row[design.names.index(name)] for row in design.x])
    low, high = design.bounds[design.names.index(name)]
    middle = (low + high) / 2.0
    below, above = y[column < middle], y[column > middle]
    return (float(below.mean()) if below.size else math.nan, float(above.mean()) if above.size else math.nan)


def _indices(design: Design, y: np.ndarray, effects: dict[str, FactorEffect], seed: int) -> None:
    """Morris's (μ, μ*, its interval, σ) or Sobol's (S1, ST and their intervals) indices into ``effects``."""
    from SALib.analyze import morris, sobol

    with warnings.catch_warnings():
        # One trajectory has no spread to estimate σ from: numpy warns and σ is NaN (shown as n/a).
        warnings.simplefilter("ignore", RuntimeWarning)
        if design.method == "morris":
            x = np.array(design.x)
            r = morris.analyze(design.problem, x, y, num_resamples=SALIB_RESAMPLES, num_levels=design.levels, seed=seed)
            for i, name in enumerate(design.names):
                e = effects[name]
                e.mu, e.mu_star = float(r["mu"][i]), float(r["mu_star"][i])
                e.mu_star_conf, e.sigma = float(r["mu_star_conf"][i]), float(r["sigma"][i])
        else:
            r = sobol.analyze(design.problem, y, calc_second_order=False, num_resamples=SALIB_RESAMPLES, seed=seed)
            for i, name in enumerate(design.names):
                e = effects[name]
                e.s1, e.s1_conf, e.st, e.st_conf = (float(r[k][i]) for k in ("S1", "S1_conf", "ST", "ST_conf"))


def analyse(design: Design, results: Results, seed: int) -> list[OutputAnalysis]:
    """Morris's or Sobol's indices for every output (module docstring)."""
    analyses = []
    for (metric, baseline), raw in outputs(results, len(design.x)).items():
        y, missing = _filled(raw)
        effects = {name: FactorEffect(name) for name in design.names}
        if missing < len(y):
            _indices(design, y, effects, seed)
            for name, e in effects.items():
                e.low_half, e.high_half = _halves(design, y, name)
        known = raw[~np.isnan(raw)]
        analyses.append(
            OutputAnalysis(
                metric,
                baseline,
                len(y),
                missing,
                float(known.mean()) if known.size else math.nan,
                float((known < 0).mean()) if known.size else math.nan,
                list(effects.values()),
            )
        )
    return analyses


def what_matters(analyses: list[OutputAnalysis], count: int) -> list[str]:
    """The ``count`` factors with the largest μ*, each output's μ* scaled by its largest (module docstring)."""
    score: dict[str, float] = {}
    for a in analyses:
        top = max((e.mu_star for e in a.effects if not math.isnan(e.mu_star)), default=0.0)
        for e in a.effects:
            scaled = e.mu_star / top if top > 0 and not math.isnan(e.mu_star) else 0.0
            score[e.name] = max(score.get(e.name, 0.0), scaled)
    return sorted(score, key=lambda n: (-score[n], n))[:count]


# ---------------------------------------------------------------------------- the command


def stage_spec(
    args: argparse.Namespace, design: Design, human: str | None, human_values: dict[str, float]
) -> SweepSpec:
    return SweepSpec(
        kind="sensitivity",
        methods=METHODS,
        robots=(args.robots,),
        objects=args.objects,
        ps=(args.p,),
        trials=args.replicates,
        seed=args.seed,
        human_config=human,
        time_limit=args.time_limit,
        human=human_values,
        points=design.points(),
        domain="detour",
        extra={"stage": design.method},
    )


def _stage(
    args: argparse.Namespace, design: Design, folder: Path, human: str | None, human_values: dict[str, float]
) -> int:
    """Run one stage's sweep in ``folder`` (its own report is the sensitivity report, not the per-point one)."""
    from .cli import run_options
    from .runner import Sweep

    if folder.joinpath(DESIGN_FILE).exists() and Design.load(folder) != design and not args.resume:
        raise ValueError(f"{folder} holds another design: choose another --out")
    design.save(folder)
    options = run_options(argparse.Namespace(**{**vars(args), "report": False}), folder)
    return Sweep(stage_spec(args, design, human, human_values), options).run()


def run_sensitivity(args: argparse.Namespace) -> int:
    """``arroch experiment sensitivity``: both stages, then the report (module docstring)."""
    from .cli import human_values, read_human_config
    from .runner import SweepError
    from .sensitivity_report import build_sensitivity_report

    try:
        out = Path(args.out or Path("experiments/results") / "sensitivity")
        ranges = _ranges(args.factors)
        human = read_human_config(args)
        extra = human_values(args)
        screened = [r.name for r in ranges]
        clash = sorted(set(extra) & set(screened))
        if clash:
            raise ValueError(f"{', '.join(clash)}: screened here, so not also set for every trial")
        morris_stage = morris_design(ranges, args.trajectories, args.levels, args.seed)
        code = _stage(args, morris_stage, out / "morris", human, extra)
        if code not in (0, 1):
            return code
        if args.sobol_n > 0 and args.sobol_factors > 0:
            screening = analyse(morris_stage, load_results(out / "morris"), args.seed)
            chosen = what_matters(screening, args.sobol_factors)
            log.info("Sobol stage on %s (largest scaled mu* in the screening)", ", ".join(chosen))
            sobol_stage = sobol_design(ranges, chosen, args.sobol_n, args.seed)
            code = max(code, _stage(args, sobol_stage, out / "sobol", human, extra))
            if code not in (0, 1):
                return code
        if args.report:
            for path in build_sensitivity_report(out, args.seed):
                log.info("wrote %s", path)
        return code
    except (ValueError, SweepError) as exc:
        log.error("%s", exc)
        return 2


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's options (the execution options are every sweep's, added by the CLI)."""
    design = parser.add_argument_group("design (decides the results)")
    design.add_argument("--trajectories", type=int, default=3, metavar="R", help="Morris trajectories (default 3)")
    design.add_argument("--levels", type=int, default=4, metavar="L", help="Morris grid levels (default 4)")
    design.add_argument(
        "--sobol-factors",
        type=int,
        default=2,
        metavar="K",
        help="factors the Sobol stage varies: the K with the largest mu* (default 2; 0: no Sobol stage)",
    )
    design.add_argument(
        "--sobol-n", type=int, default=4, metavar="N", help="Sobol base points, a power of 2 (default 4: a screening)"
    )
    design.add_argument(
        "--replicates", type=int, default=1, metavar="T", help="trials per point and method (default 1)"
    )
    design.add_argument(
        "--factors",
        type=lambda text: [part.strip() for part in text.split(",") if part.strip()],
        default=None,
        metavar="F,F,...",
        help=f"screen only these (default all: {', '.join(r.name for r in SCREEN)})",
    )
    design.add_argument("--robots", type=int, default=2, metavar="N", help="team size (default 2)")
    design.add_argument("--objects", type=int, default=3, metavar="K", help="objects per robot (default 3)")
    design.add_argument(
        "--p", type=float, default=0.5, metavar="P", help="the human's door-opening probability (default 0.5)"
    )
    design.add_argument("--seed", type=int, default=0, help="base seed of the samples and the trials (default 0)")
