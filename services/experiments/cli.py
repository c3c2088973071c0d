"""``arroch experiment robots|laziness|map|report``: the paper's simulation experiments (§V-A), and a
map of where feedback pays (the human's task length × the cost of an interruption).

Each trial runs the real planner, restrictor and sim (its human model) as separate processes over
Zenoh, in lockstep mode, on a site generated from the trial's seed. Trials run ``--jobs`` at a time
and are recorded in DIR/trials.csv as they end (a crash loses nothing finished); ``--resume``
continues an interrupted sweep. The same options give the same trials.csv byte for byte, on a quiet
machine or a loaded one, locally or on a Dask cluster (``--cluster``). Trials are paired: for one
trial index every method meets the same site and the same human draws. When the sweep is complete
the report is built (``arroch experiment report DIR`` rebuilds it from the CSV).

Examples:
  arroch experiment robots --robots 2,3,4,5,6 --objects 3 --trials 30 --seed 0 --out experiments/results/robots
  arroch experiment laziness --p 0.05,0.1,0.2,0.4,0.6,0.8,1.0 --robots 3 --out experiments/results/laziness
  arroch experiment map --task-means 150,300,600,900 --costs 0,15,60 --trials 20 --out experiments/results/map
  arroch experiment robots --robots 2 --objects 1 --trials 2 --methods arroch --out /tmp/tiny
  arroch experiment robots --cluster tcp://scheduler:8786 --out /tmp/on-a-cluster
  arroch experiment report experiments/results/robots
"""

from __future__ import annotations

import argparse
import logging
import os
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .design import DEFAULT_COST, DEFAULT_P, DEFAULT_TASK, FOCUS_READINGS, METHODS, SweepSpec, format_p

log = logging.getLogger("arroch.experiment")


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
    sweep.add_argument(
        "--objects", type=int, default=3, metavar="K", help="objects per robot (default 3, as in the paper)"
    )
    trials = 20 if kind == "map" else 30
    sweep.add_argument(
        "--trials",
        type=int,
        default=trials,
        metavar="T",
        help=f"trials per condition (default {trials}"
        + ("; 36 conditions x 20 fit the 30-minute budget on 2 cores)" if kind == "map" else ")"),
    )
    sweep.add_argument(
        "--methods", type=_methods, default=METHODS, metavar="M,M,...", help=f"methods (default {','.join(METHODS)})"
    )
    sweep.add_argument("--seed", type=int, default=0, help="base seed; every trial's seeds derive from it (default 0)")
    sweep.add_argument(
        "--human-config",
        metavar="FILE",
        help="the sim's --human-config for every trial (default: the sim's human model, the paper's; "
        "for quick checks only: results under another model are not the paper's experiment)",
    )
    sweep.add_argument(
        "--time-limit", type=float, metavar="S", help="the sim's --time-limit in sim seconds (default: the sim's, 7200)"
    )
    run = parser.add_argument_group("execution (decides only the speed)")
    run.add_argument(
        "--out", type=Path, default=None, metavar="DIR", help=f"results folder (default experiments/results/{kind})"
    )
    run.add_argument(
        "--resume", action="store_true", help="continue the sweep in DIR: finished trials are kept, the others run"
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


def _spec(args: argparse.Namespace) -> SweepSpec:
    human = None
    if args.human_config:
        try:
            human = Path(args.human_config).read_text(encoding="utf-8")
        except OSError as exc:
            raise ValueError(f"--human-config {args.human_config}: {exc.strerror}") from None
    if args.kind == "robots":
        robots, ps = args.robots, (args.p if args.p is not None else DEFAULT_P,)
    elif args.kind == "map":
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
    )


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


def run_sweep(args: argparse.Namespace) -> int:
    from .runner import RunOptions, Sweep, SweepError
    from .trial import TrialConfig

    try:
        spec = _spec(args)
        out = args.out or Path("experiments/results") / args.kind
        options = RunOptions(
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
        )
        sweep = Sweep(spec, options)
        return sweep.run()
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
    ):
        p = sub.add_parser(
            kind, help=text, description=f"{text}.\n\n{__doc__}", formatter_class=argparse.RawDescriptionHelpFormatter
        )
        _add_sweep_arguments(p, kind)
        p.set_defaults(func=run_sweep, kind=kind)
    report = sub.add_parser("report", help="rebuild a results folder's tables, figures, tests and claims from its CSV")
    report.add_argument("dir", type=Path, metavar="DIR", help="a results folder (with trials.csv)")
    report.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    report.set_defaults(func=run_report)
