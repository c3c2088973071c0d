"""``arroch experiment robots|laziness|map|detour|sensitivity|population|report``: the paper's simulation
experiments (§V-A), a map of where feedback pays (the human's task length × the cost of an
interruption), and the experiments on ARROCH's mechanism: a task the planner can reorder around her
unavailability (``detour``), a sensitivity analysis of the human model and the domain
(``sensitivity``), and a population of simulated people (``population``).

Each trial runs the real planner, restrictor and sim (its human model) as separate processes over
Zenoh, in lockstep mode, on a site generated from the trial's seed. Trials run ``--jobs`` at a time
and are recorded in DIR/trials.csv as they end (a crash loses nothing finished); ``--resume``
continues an interrupted sweep. The same options give the same trials.csv byte for byte on a quiet
machine, locally or on a Dask cluster (``--cluster``); under load about 1 row in 100 has come out
differently (cause open: experiments/README.md, Reproducing).
Trials are paired: for one trial index every method meets the same site and the same human draws.
When the sweep is complete the report is built (``arroch experiment report DIR`` rebuilds it from
the CSV).

Examples:
  arroch experiment robots --robots 2,3,4,5,6 --objects 3 --trials 30 --seed 0 --out experiments/results/robots
  arroch experiment laziness --p 0.05,0.1,0.2,0.4,0.6,0.8,1.0 --robots 3 --out experiments/results/laziness
  arroch experiment map --task-means 150,300,600,900 --costs 0,15,60 --trials 20 --out experiments/results/map
  arroch experiment detour --capacities 1,2,3 --door-shares 0.5 --robots 2 --objects 3 --out /tmp/detour
  arroch experiment sensitivity --out /tmp/sensitivity
  arroch experiment population --population studies/pilot/human.toml --persons 12 --out /tmp/population
  arroch experiment robots --robots 2 --objects 1 --trials 2 --methods arroch --out /tmp/tiny
  arroch experiment robots --cluster tcp://scheduler:8786 --out /tmp/on-a-cluster
  arroch experiment report experiments/results/robots
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .design import (
    DEFAULT_COST,
    DEFAULT_DOOR_SHARE,
    DEFAULT_P,
    DEFAULT_TASK,
    FOCUS_READINGS,
    METHODS,
    SweepSpec,
    format_p,
)

log = logging.getLogger("arroch.experiment")

# Trials per condition by default (30 elsewhere), each sized for the 30-minute budget of this 2-core machine: the
# map's 36 cells x 20; the detour's 3 capacities x 15 (trials measured here at ~8, ~28 and ~41 s wall at capacity
# 1, 2 and 3: 15 x 3 methods x 77 s / 2 jobs = 29 min); a population's persons x 2.
DEFAULT_TRIALS = {"map": 20, "detour": 15, "population": 2}
DEFAULT_PERSONS = 12  # simulated people of a population sweep: 12 x 2 missions x 3 methods fit ~10 minutes


def _list(kind: Callable[[str], Any], what: str) -> Callable[[str], tuple[Any, ...]]:
    def parse(text: str) -> tuple[Any, ...]:
        parts = [part.strip() for part in text.split(",") if part.strip()]
        if not parts:
            raise argparse.ArgumentTypeError(f"expected a comma-separated list of {what}")
        try:
            return tuple(kind(part) for part in parts)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a comma-separated list of {what}, got {text!r}") from None

    return parse


def _methods(text: str) -> tuple[str, ...]:
    methods = _list(str, "methods")(text)
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown method(s) {', '.join(unknown)} (known: {', '.join(METHODS)})")
    return methods


def _add_sweep_arguments(parser: argparse.ArgumentParser, kind: str) -> None:
    sweep = parser.add_argument_group("sweep (decides the results)")
    if kind == "map":
        sweep.add_argument(
            "--task-means",
            type=_list(float, "task lengths in seconds"),
            default=(150.0, 300.0, 600.0, 900.0),
            metavar="S,S,...",
            help="the human's mean task length, s (default 150,300,600,900)",
        )
        sweep.add_argument(
            "--costs",
            type=_list(float, "interruption costs in seconds"),
            default=(0.0, 15.0, 60.0),
            metavar="S,S,...",
            help="seconds of her task lost per interruption (default 0,15,60)",
        )
        sweep.add_argument("--robots", type=int, default=3, metavar="N", help="team size (default 3)")
        sweep.add_argument(
            "--p",
            type=float,
            default=None,
            metavar="P",
            help=f"the human's door-opening probability (default: the sim's, {format_p(DEFAULT_P)})",
        )
    elif kind == "detour":
        sweep.add_argument(
            "--capacities",
            type=_list(int, "robot capacities"),
            default=(1, 2, 3),
            metavar="C,C,...",
            help="objects a robot carries at once (default 1,2,3: the issue's factor)",
        )
        sweep.add_argument(
            "--door-shares",
            type=_list(float, "shares in [0, 1]"),
            default=(DEFAULT_DOOR_SHARE,),
            metavar="S,S,...",
            help=f"share of the deliveries behind her door (default {DEFAULT_DOOR_SHARE:g}; 1 is the paper's task)",
        )
        sweep.add_argument(
            "--door-hold",
            type=float,
            default=None,
            metavar="S",
            help="s her door stays open after she opens it (default: the site's, 20)",
        )
        sweep.add_argument("--robots", type=int, default=2, metavar="N", help="team size (default 2)")
        sweep.add_argument(
            "--p",
            type=float,
            default=None,
            metavar="P",
            help=f"the human's door-opening probability (default: the sim's, {format_p(DEFAULT_P)})",
        )
    elif kind == "robots":
        sweep.add_argument(
            "--robots",
            type=_list(int, "team sizes"),
            default=(2, 3, 4, 5, 6),
            metavar="N,N,...",
            help="team sizes (default 2,3,4,5,6)",
        )
        sweep.add_argument(
            "--p",
            type=float,
            default=None,
            metavar="P",
            help=f"the human's door-opening probability (default: the sim's, {format_p(DEFAULT_P)})",
        )
    elif kind == "population":
        sweep.add_argument(
            "--population",
            type=Path,
            required=True,
            metavar="FILE",
            help="the people's distributions: [population.<factor>] priors, or what `arroch study calibrate` writes "
            "([human] values, [calibration.<factor>] estimate, interval, n)",
        )
        sweep.add_argument(
            "--persons",
            type=int,
            default=DEFAULT_PERSONS,
            metavar="N",
            help=f"simulated people (default {DEFAULT_PERSONS})",
        )
        sweep.add_argument(
            "--domain",
            choices=("paper", "detour"),
            default="paper",
            help="the buildings (default paper: every delivery through her door; detour: only --door-share of them)",
        )
        sweep.add_argument("--capacity", type=int, default=None, metavar="C", help="robot capacity (default: 1)")
        sweep.add_argument(
            "--door-share",
            type=float,
            default=None,
            metavar="S",
            help=f"detour domain: share of deliveries behind her door (default {DEFAULT_DOOR_SHARE:g})",
        )
        sweep.add_argument("--robots", type=int, default=2, metavar="N", help="team size (default 2)")
        sweep.add_argument(
            "--p",
            type=float,
            default=None,
            metavar="P",
            help=f"door-opening probability where the file sets none (default: the sim's, {format_p(DEFAULT_P)})",
        )
    else:
        sweep.add_argument(
            "--p",
            type=_list(float, "probabilities"),
            default=(0.05, 0.1, 0.2, 0.4, 0.6, 0.8, 1.0),
            metavar="P,P,...",
            help="door-opening probabilities (default 0.05,0.1,0.2,0.4,0.6,0.8,1.0)",
        )
        sweep.add_argument("--robots", type=int, default=3, metavar="N", help="team size (default 3)")
    if kind != "map":
        sweep.add_argument(
            "--task-mean",
            type=float,
            default=None,
            metavar="S",
            help=f"the human's mean task length, s (default: --human-config's, else the sim's, {DEFAULT_TASK:g})",
        )
        sweep.add_argument(
            "--interruption-cost",
            type=float,
            default=None,
            metavar="S",
            help="seconds of her task lost per interruption of a focus interval "
            f"(default: --human-config's, else the sim's, {DEFAULT_COST:g})",
        )
    sweep.add_argument(
        "--focus-reading",
        choices=FOCUS_READINGS,
        default=None,
        help="faithful (the sim's default): only a declared focus interval keeps her from doors; strict: any does",
    )
    add_human_arguments(sweep)
    sweep.add_argument(
        "--objects", type=int, default=3, metavar="K", help="objects per robot (default 3, as in the paper)"
    )
    trials = DEFAULT_TRIALS.get(kind, 30)
    sweep.add_argument(
        "--trials",
        type=int,
        default=trials,
        metavar="T",
        help=f"trials per condition (default {trials}"
        + ("; 36 conditions x 20 fit the 30-minute budget on 2 cores)" if kind == "map" else ")"),
    )
    add_common_arguments(parser, sweep, kind)


def _number(lo: float, hi: float = math.inf) -> Callable[[str], float]:
    """A finite number in [lo, hi], refused by argparse (exit 2, naming the option) before anything starts."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not (math.isfinite(value) and lo <= value <= hi):
            bound = f"[{lo:g}, {hi:g}]" if math.isfinite(hi) else f">= {lo:g}"
            raise argparse.ArgumentTypeError(f"must be {bound}, got {text}")
        return value

    return parse


def add_human_arguments(group: argparse._ArgumentGroup) -> None:
    """The human-model options every sweep takes; unset, the sim's defaults (all off) hold."""
    group.add_argument(
        "--anticipation",
        type=_number(0.0),
        default=None,
        metavar="S",
        help="she may leave for her door when a robot's planned arrival there is this many s ahead "
        "(AR methods only; default 0: off)",
    )
    group.add_argument(
        "--focus-fraction",
        type=_number(0.0, 0.9),  # the intervals must fit in her task (the sim's limit)
        default=None,
        metavar="F",
        help="share of her task in focus intervals, fixed whatever her task length (default: off, whole-minute "
        "intervals of 2-4 minutes)",
    )
    group.add_argument(
        "--focus-responsiveness",
        type=_number(0.0, 1.0),
        default=None,
        metavar="R",
        help="x her chances during a focus interval she did not declare (default 1: faithful; 0: she stays)",
    )


def human_values(args: argparse.Namespace) -> dict[str, float]:
    names = ("anticipation", "focus_fraction", "focus_responsiveness")
    return {name: float(getattr(args, name)) for name in names if getattr(args, name, None) is not None}


def add_common_arguments(parser: argparse.ArgumentParser, sweep: argparse._ArgumentGroup, kind: str) -> None:
    """The methods, seed, model and execution options every sweep takes."""
    sweep.add_argument(
        "--methods", type=_methods, default=METHODS, metavar="M,M,...", help=f"methods (default {','.join(METHODS)})"
    )
    sweep.add_argument("--seed", type=int, default=0, help="base seed; every trial's seeds derive from it (default 0)")
    add_model_arguments(sweep)
    add_run_arguments(parser, kind)


def add_model_arguments(sweep: argparse._ArgumentGroup) -> None:
    """--human-config and --time-limit (the sensitivity analysis takes them too)."""
    sweep.add_argument(
        "--human-config",
        metavar="FILE",
        help="the sim's --human-config for every trial (default: the sim's human model, the paper's; "
        "for quick checks only: results under another model are not the paper's experiment)",
    )
    sweep.add_argument(
        "--time-limit", type=float, metavar="S", help="the sim's --time-limit in sim seconds (default: the sim's, 7200)"
    )


def add_run_arguments(parser: argparse.ArgumentParser, kind: str) -> None:
    """The execution options: they decide only the speed."""
    run = parser.add_argument_group("execution (decides only the speed)")
    run.add_argument(
        "--out", type=Path, default=None, metavar="DIR", help=f"results folder (default experiments/results/{kind})"
    )
    run.add_argument(
        "--resume", action="store_true", help="continue the sweep in DIR: finished trials are kept, the others run"
    )
    run.add_argument(
        "--rerun",
        action="append",
        default=[],
        metavar="TRIAL",
        help="with --resume: run this recorded trial again (its name as in the logs, e.g. "
        "arroch-n3-o3-p0.5-w600-c0-t02; repeatable), as after a fix that concerns only some trials; "
        "the report then names both code versions",
    )
    run.add_argument(
        "--jobs",
        type=int,
        default=os.cpu_count() or 1,
        metavar="N",
        help=f"trials at once (default {os.cpu_count()}: the cores)",
    )
    run.add_argument(
        "--cluster",
        metavar="tcp://HOST:PORT",
        help="run the trials on this Dask distributed scheduler's workers (each trial with its own router there) "
        "instead of --jobs local workers; needs pip install 'arroch[cluster]'",
    )
    run.add_argument(
        "--cluster-timeout",
        type=float,
        default=20.0,
        metavar="S",
        help="wall s to reach the --cluster scheduler before the sweep is refused (default 20)",
    )
    run.add_argument(
        "--router",
        choices=("worker", "shared", "trial"),
        default="worker",
        help="Zenoh router per worker (default), one shared by all, or one per trial",
    )
    run.add_argument(
        "--trial-timeout",
        type=float,
        default=300.0,
        metavar="S",
        help="wall seconds before a trial is given up as a timeout (default 300: a 6-robot trial takes ~10-50 s)",
    )
    run.add_argument(
        "--service-log-level",
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        default="WARNING",
        help="log level of the trials' services (default WARNING; their output is kept for failed trials)",
    )
    run.add_argument(
        "--progress",
        choices=("auto", "bar", "line", "off"),
        default="auto",
        help="a bar on a terminal (auto), a line every 30 s, or nothing",
    )
    run.add_argument(
        "--keep-events",
        action="store_true",
        help="keep every trial's event log in DIR/events/<trial>.jsonl (the sim's --events-out; to compare runs)",
    )
    run.add_argument(
        "--record",
        choices=("failed", "all", "none"),
        default="failed",
        help="record each trial (arroch record) and keep the recordings of failed trials (timeout, error; default), "
        "of all trials, or none (no recorder) in DIR/recordings/<trial>.mcap",
    )
    run.add_argument("--no-report", dest="report", action="store_false", help="do not build the report at the end")
    parser.add_argument(
        "--log-level",
        default=None,
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        help="this command's log level (env ARROCH_LOG_LEVEL, default INFO)",
    )


def read_human_config(args: argparse.Namespace) -> str | None:
    """The text of --human-config, or None."""
    if not args.human_config:
        return None
    try:
        return Path(args.human_config).read_text(encoding="utf-8")
    except OSError as exc:
        raise ValueError(f"--human-config {args.human_config}: {exc.strerror}") from None


def _detour_points(args: argparse.Namespace) -> tuple[dict[str, float], ...]:
    hold = {"door_hold": args.door_hold} if args.door_hold is not None else {}
    return tuple({"capacity": c, "door_share": s, **hold} for c in args.capacities for s in args.door_shares)


def _spec(args: argparse.Namespace) -> SweepSpec:
    human = read_human_config(args)
    if args.kind == "robots":
        robots, ps = args.robots, (args.p if args.p is not None else DEFAULT_P,)
    elif args.kind in ("map", "detour", "population"):
        robots, ps = (args.robots,), (args.p if args.p is not None else DEFAULT_P,)
    else:
        robots, ps = (args.robots,), args.p
    if args.kind == "map":
        tasks, costs = args.task_means, args.costs
    else:
        tasks = (args.task_mean if args.task_mean is not None else _from_human(human, "task_mean", DEFAULT_TASK),)
        costs = (
            args.interruption_cost
            if args.interruption_cost is not None
            else _from_human(human, "interruption_cost", DEFAULT_COST),
        )
    points: tuple[dict[str, float], ...] = ()
    shared, extra, domain = human_values(args), {}, "paper"
    if args.kind == "detour":
        points, domain = _detour_points(args), "detour"
    elif args.kind == "population":
        points, shared, extra = _population(args, shared)
        domain = args.domain
    return SweepSpec(
        kind=args.kind,
        methods=args.methods,
        robots=tuple(robots),
        objects=args.objects,
        ps=tuple(ps),
        trials=args.trials,
        seed=args.seed,
        tasks=tuple(tasks),
        costs=tuple(costs),
        human_config=human,
        focus_reading=args.focus_reading,
        time_limit=args.time_limit,
        extra=extra,
        human=shared,
        points=points,
        domain=domain,
    )


def _population(
    args: argparse.Namespace, shared: dict[str, float]
) -> tuple[tuple[dict[str, float], ...], dict[str, Any], dict[str, Any]]:
    """The persons (points), the human values all of them share, and what the report says of the priors."""
    from .population import load_population

    if args.domain != "detour" and args.door_share is not None:
        raise ValueError("--door-share goes with --domain detour")
    population = load_population(args.population)
    site = {"capacity": args.capacity} if args.capacity is not None else {}
    if args.door_share is not None:
        site["door_share"] = args.door_share
    persons = tuple({**site, **person} for person in population.persons(args.persons, args.seed))
    extra = {"priors": [p.describe() for p in population.priors]}
    if population.unused:
        extra["calibrated but not a factor here"] = population.unused
    return persons, {**population.human, **shared}, extra


def _from_human(text: str | None, name: str, default: float) -> float:
    """``name`` from a --human-config text (its [human] table or top level), else ``default``: the
    value the trials' human model has, which the CSV records with every trial."""
    if text is None:
        return default
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"--human-config: {exc}") from None
    value = data.get("human", data).get(name, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"--human-config: {name} must be a number")
    return float(value)


def run_options(args: argparse.Namespace, out: Path) -> Any:
    """The execution options (``RunOptions``) of a sweep written to ``out``."""
    from .runner import RunOptions
    from .trial import TrialConfig

    return RunOptions(
        out=out,
        jobs=args.jobs,
        router=args.router,
        resume=args.resume,
        progress=args.progress,
        report=args.report,
        trial=TrialConfig(
            timeout=args.trial_timeout,
            log_level=args.service_log_level,
            events_dir=None,
            record=args.record,
            recordings_dir=(Path(out) / "recordings").resolve(),
        ),
        keep_events=args.keep_events,
        cluster=args.cluster,
        cluster_timeout=args.cluster_timeout,
        rerun=tuple(args.rerun),
    )


def run_sweep(args: argparse.Namespace) -> int:
    from .runner import Sweep, SweepError

    try:
        spec = _spec(args)
        out = args.out or Path("experiments/results") / args.kind
        return Sweep(spec, run_options(args, out)).run()
    except (ValueError, SweepError) as exc:
        log.error("%s", exc)
        return 2


def run_report(args: argparse.Namespace) -> int:
    from .report import ReportError, build_report

    try:
        written = build_report(args.dir)
    except (ReportError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return 2
    for path in written:
        print(path)
    return 0


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "experiment",
        help="the paper's simulation experiments: sweeps and their report",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.set_defaults(func=lambda _args: parser.print_help() or 2)
    sub = parser.add_subparsers(dest="experiment", metavar="SWEEP")
    for kind, text in (
        ("robots", "vary the number of robots (paper: figure 'different number of robots')"),
        ("laziness", "vary the human's door-opening probability (paper: figure 'human laziness')"),
        ("map", "where feedback pays: the human's task length x the cost of an interruption, all methods paired"),
        ("detour", "a task the planner can reorder: only some deliveries behind her door, robot capacity 1-3"),
        ("population", "a population of simulated people drawn from stated or calibrated priors, with a mixed model"),
    ):
        p = sub.add_parser(
            kind, help=text, description=f"{text}.\n\n{__doc__}", formatter_class=argparse.RawDescriptionHelpFormatter
        )
        _add_sweep_arguments(p, kind)
        p.set_defaults(func=run_sweep, kind=kind)
    _register_sensitivity(sub)
    report = sub.add_parser("report", help="rebuild a results folder's tables, figures, tests and claims from its CSV")
    report.add_argument("dir", type=Path, metavar="DIR", help="a results folder (with trials.csv)")
    report.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    report.set_defaults(func=run_report)


def _register_sensitivity(sub: Any) -> None:
    from . import sensitivity

    text = "which human-model and domain parameters decide ARROCH's differences (Morris, then Sobol; SALib)"
    p = sub.add_parser(
        "sensitivity",
        help=text,
        description=f"{text}.\n\n{sensitivity.__doc__}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sensitivity.add_arguments(p)
    model = p.add_argument_group("model (decides the results)")
    add_human_arguments(model)
    add_model_arguments(model)
    add_run_arguments(p, "sensitivity")
    p.set_defaults(func=sensitivity.run_sensitivity, kind="sensitivity")
