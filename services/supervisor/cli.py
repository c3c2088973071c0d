"""``arroch up``: run a router and the ARROCH services as supervised child processes.

Starts ``arroch router`` on a free localhost port (or ``--router-listen``; or none with
``--no-router``), then the chosen services, each in its own process group, all connected to that
router and sharing one ``--namespace``. Their output is merged with a ``[name]`` prefix. A child
that crashes is restarted with exponential backoff (at most ``--max-restarts`` a minute); progress
(deliveries per robot, door openings, site time) is shown as a bar on a terminal, a periodic line
otherwise. Ctrl-C or SIGTERM stops everything (SIGTERM, then SIGKILL after ``--stop-timeout``);
with ``--until-done`` the run also ends when the ``mission_done`` event arrives, and its metrics
are printed. Each run leaves ``<run-dir>/<timestamp>/`` with supervisor.log, events.jsonl,
metrics.json (when the mission finished) and run.json.

Examples:
  arroch up --until-done                                   # the default mission on the office site
  arroch up --services planner,sim --method arroch --rate 10
  arroch up --services ping --child 'pinger={python} -m services.cli ping send --count 50'
  arroch up --no-router --zenoh-config-dir /etc/arroch/zenoh --services sim   # one host of several
  arroch up --services planner,restrictor,sim,ar,tablet --camera tablet --until-done   # what `arroch demo` runs
  arroch up --services planner,restrictor,sim,ar,tablet --human participant --study-trial trial.json   # a study trial
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
from pathlib import Path

from runtime.clock import make_clock
from runtime.launch.catalog import (
    DEFAULT_SERVICES,
    RECORDER,
    SERVICES,
    SUPERVISOR_ROLE,
    VIEWER,
    Launch,
    MissionOptions,
    parse_child,
    parse_services,
)
from runtime.runner import LOG_FORMAT, add_common_arguments
from runtime.transport import DEFAULT_ROUTER, ZenohOptions, free_tcp_port

from .output import Output, OutputHandler
from .supervisor import Supervisor, UpConfig

log = logging.getLogger("arroch.up")


def _namespace(args: argparse.Namespace) -> str:
    if args.namespace:
        from protocol.keys import Keys

        Keys(args.namespace)  # ValueError (exit 2) for a name that cannot be a key chunk
        return args.namespace
    from runtime.runner import namespace_from  # loads the site file: only when the name is needed

    return namespace_from(args)


def _totals(site: str | None) -> dict[str, int] | None:
    """Objects each robot must deliver, from the site file; None when the site cannot tell."""
    try:
        from protocol.site import load_site
    except ImportError:
        return None
    loaded = load_site(site)
    totals = {rid: 0 for rid in loaded.robots}
    for obj in loaded.objects.values():
        totals[obj.robot] = totals.get(obj.robot, 0) + 1
    return totals


def _connect_for(listen: str) -> str:
    """Where local children dial a router listening on ``listen`` (any-address → loopback)."""
    proto, _, address = listen.partition("/")
    host, _, port = address.rpartition(":")
    if host in ("0.0.0.0", "[::]", "::", ""):
        host = "127.0.0.1"
    return f"{proto}/{host}:{port}"


def _recording(args: argparse.Namespace, services: list) -> list:
    """The recorder to add: by default to every run with a sim; --record always, --no-record never (but --view)."""
    record = args.record if args.record is not None else any(s.name == "sim" for s in services)
    if record and args.record_profile == "ros2":
        # run.mcap as always (runs show, replay read it), and the run as a ROS 2 bag in <run>/run_ros2/.
        extra = ("--profile", "foxglove,ros2", "--ros-distro", args.ros_distro)
        return [dataclasses.replace(RECORDER, command=(*RECORDER.command, *extra))]
    if args.record_profile == "ros2":
        raise ValueError("--record-profile ros2 records the run as a ROS 2 bag too: not with --no-record")
    if record:
        return [RECORDER]
    return [VIEWER] if args.view else []


def build_config(args: argparse.Namespace) -> tuple[UpConfig, ZenohOptions]:
    """Check the options and turn them into the supervisor's configuration (ValueError if wrong)."""
    services = parse_services(args.services)
    services += _recording(args, services)
    config_dir = Path(args.zenoh_config_dir).resolve() if args.zenoh_config_dir else None
    if config_dir is not None:
        needed = (
            list(dict.fromkeys(s.identity for s in services)) + [SUPERVISOR_ROLE] + (["router"] if args.router else [])
        )
        missing = [f"{config_dir / name}.json5" for name in needed if not (config_dir / f"{name}.json5").is_file()]
        if missing:
            raise ValueError(
                f"missing Zenoh configs {', '.join(missing)} (arroch deploy render --out-dir {config_dir})"
            )
    if args.time_limit is not None and args.time_limit < 0:
        raise ValueError(f"--time-limit must be >= 0 site seconds (0: never), got {args.time_limit:g}")
    if args.rate is not None and args.rate <= 0:
        raise ValueError(f"--rate must be positive, got {args.rate}")
    if args.linger and not args.until_done:
        raise ValueError("--linger keeps a run up after its mission: it goes with --until-done")
    if args.human == "participant" and args.mode == "lockstep":
        raise ValueError(
            "--human participant: a person acts in real time, so the simulation cannot run in lockstep "
            "(leave --mode out for realtime, or give --rate K)"
        )
    if args.doors == "sensor" and args.human != "participant":
        raise ValueError("--doors sensor: real doors are opened by a real person: it goes with --human participant")
    study_trial = None
    if args.study_trial:
        path = Path(args.study_trial)
        if not path.is_file():
            raise ValueError(f"--study-trial {args.study_trial}: no such file")
        study_trial = str(path.resolve())  # the children may run elsewhere than here
    if args.rate is not None and args.mode not in (None, "rate", "lockstep"):
        raise ValueError(
            "--rate K runs the simulation K times faster (at most, in lockstep); it does not go with --mode "
            f"{args.mode}"
        )
    router_listen = args.router_listen
    if args.router and router_listen is None and config_dir is None:
        router_listen = f"tcp/127.0.0.1:{free_tcp_port()}"
    if not args.router and router_listen:
        raise ValueError("--router-listen makes no sense with --no-router")
    if args.router and args.connect:
        raise ValueError("--connect is for --no-router (a router started elsewhere)")
    if config_dir is not None:
        connect: list[str] = []
    elif args.router:
        connect = [_connect_for(router_listen)]
    else:
        connect = [part.strip() for part in (args.connect or DEFAULT_ROUTER).split(",") if part.strip()]
    launch = Launch(
        namespace=_namespace(args),
        connect=connect,
        zenoh_config_dir=config_dir,
        site=args.site,
        clock=args.clock if args.clock != "sim" else None,
        log_level=args.log_level,
        mission=MissionOptions(
            method=args.method,
            mode=args.mode,
            rate=args.rate,
            seed=args.seed,
            time_limit=args.time_limit,
            camera=args.camera,
            camera_every=args.camera_every,
            view_port=args.view_port if args.view else None,
            human=args.human,
            doors=args.doors,
            study_trial=study_trial,
        ),
    )
    extra = [parse_child(entry, launch) for entry in args.child or []]
    names = [s.name for s in services] + [name for name, _ in extra]
    if len(set(names)) != len(names):
        raise ValueError(f"two children share a name in {', '.join(names)}")
    if not names and not args.router:
        raise ValueError("nothing to run: no services, no --child, and --no-router")
    totals = _totals(args.site) if any(s.name == "sim" for s in services) or args.until_done else None
    config = UpConfig(
        services=services,
        launch=launch,
        extra_children=extra,
        start_router=args.router,
        router_listen=router_listen,
        until_done=args.until_done,
        linger=args.linger,
        timeout=args.timeout,
        run_base=Path(args.run_dir),
        progress_interval=args.progress_interval or (0.5 if args.progress == "bar" else 5.0),
        stop_timeout=args.stop_timeout,
        start_timeout=args.start_timeout,
        max_restarts=args.max_restarts,
        totals=totals,
    )
    if config_dir is not None:
        options = ZenohOptions(config_file=str(config_dir / f"{SUPERVISOR_ROLE}.json5"))
    else:
        options = ZenohOptions(mode="client", connect=connect)
    return config, options


def run_up(args: argparse.Namespace) -> int:
    if args.progress == "auto":
        args.progress = "bar" if sys.stdout.isatty() else "line"
    output = Output(sys.stdout, bar=args.progress == "bar")
    # The supervisor's own log lines join the merged output as "[up] ..." (not raw on stderr,
    # where they would tear the progress bar).
    handler = OutputHandler(output)
    handler.setFormatter(logging.Formatter(LOG_FORMAT))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    try:
        config, options = build_config(args)
    except (ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return 2
    if args.progress == "off":
        config.progress_interval = 1e9
    return Supervisor(config, output, options, clock=make_clock(args.clock)).main()


def add_up_arguments(parser: argparse.ArgumentParser) -> None:
    add_common_arguments(parser, zenoh=False)  # --site, --namespace, --clock, --log-level (passed on)
    known = ", ".join(f"{name} ({spec.help})" for name, spec in SERVICES.items())
    parser.add_argument(
        "--services",
        metavar="LIST",
        help=f"comma-separated services to run (default {','.join(DEFAULT_SERVICES)}; '' for none). Known: {known}",
    )
    parser.add_argument(
        "--child",
        action="append",
        metavar="NAME=COMMAND",
        help="also run and supervise COMMAND as NAME (repeatable); {python} {connect} {namespace} {site} are filled in",
    )
    mission = parser.add_argument_group("mission (passed to the services that take them)")
    mission.add_argument("--method", help="planning method / baseline (e.g. arroch, no-feedback, no-comm)")
    mission.add_argument(
        "--mode",
        choices=("realtime", "rate", "lockstep"),
        help="simulation clock: realtime (the default: the default mission then takes about 11 minutes, as on the "
        "site), rate (with --rate) or lockstep (time advances only when every request is answered: the same "
        "mission in seconds; `arroch demo` paces it to about a minute)",
    )
    mission.add_argument(
        "--rate", type=float, metavar="K", help="simulate at K times real time (with --mode lockstep: at most)"
    )
    mission.add_argument("--seed", type=int, metavar="N", help="random seed of the simulation")
    mission.add_argument(
        "--time-limit",
        type=float,
        metavar="S",
        help="the sim ends the mission unfinished after S site seconds (default the sim's, 7200; 0: never)",
    )
    mission.add_argument(
        "--camera",
        metavar="SPEC",
        help="the sim's virtual camera: 'tablet' (the human's tablet) or X,Y,Z,YAW,PITCH; "
        "the ar client and the tablet page (viewer mode) show it",
    )
    mission.add_argument(
        "--camera-every",
        type=float,
        metavar="S",
        help="lockstep with --camera: a frame every S site seconds besides the held ones, so a recording or a "
        "page is smooth (default none: each frame costs a render, the AR client's turn and the recorder's; "
        "arroch demo asks for 2)",
    )
    study = parser.add_argument_group("study trials (docs/study.md)")
    study.add_argument(
        "--human",
        choices=("simulated", "participant"),
        help="who plays the human in the sim: simulated (default, the human model) or participant (a person, "
        "on her tablet page). participant needs site time that follows the wall clock: without --mode it runs "
        "realtime; --rate K is allowed, --mode lockstep is refused",
    )
    study.add_argument(
        "--doors",
        choices=("sim", "sensor"),
        help="the sim's human-operated doors: sim (default) or sensor (real doors: they follow DoorState on "
        "door/<door>/sensor from a door controller, `arroch ros2 bridge` or the experimenter's console); "
        "with --human participant",
    )
    study.add_argument(
        "--study-trial",
        metavar="FILE",
        help="the trial file (arroch study plan/run) the tablet page shows: its condition and task",
    )
    view = parser.add_argument_group("recording and live view")
    view.add_argument(
        "--record",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="record the run to <run folder>/run.mcap (default: when the run has a sim; arroch runs show DIR reads it)",
    )
    view.add_argument(
        "--record-profile",
        choices=("foxglove", "ros2"),
        default="foxglove",
        help="foxglove (default): run.mcap; ros2: run.mcap and the run as a ROS 2 bag in <run folder>/run_ros2/ "
        "(ros2 bag play, RViz 2)",
    )
    view.add_argument(
        "--ros-distro",
        choices=("humble", "jazzy"),  # the recorder's --ros-distro
        default="jazzy",
        help="with --record-profile ros2: the ROS 2 distribution whose rosbag2 reads the bag (default jazzy)",
    )
    view.add_argument(
        "--view",
        action="store_true",
        help="serve the run live to Foxglove (WebSocket; layout docs/foxglove-layout.json)",
    )
    view.add_argument(
        "--view-port", type=int, default=8765, metavar="PORT", help="with --view: the port (default 8765)"
    )
    run = parser.add_argument_group("supervision")
    run.add_argument(
        "--until-done", action="store_true", help="stop when the mission_done event arrives and print its metrics"
    )
    run.add_argument(
        "--linger",
        action="store_true",
        help="with --until-done: after the mission, print its metrics and keep everything up (the tablet page "
        "included) until Ctrl-C",
    )
    run.add_argument(
        "--timeout", type=float, metavar="S", help="give up (exit 1) after S seconds (not once --linger holds a run)"
    )
    run.add_argument(
        "--run-dir", default="runs", metavar="DIR", help="where runs/<timestamp>/ folders go (default ./runs)"
    )
    run.add_argument(
        "--progress",
        choices=("auto", "bar", "line", "off"),
        default="auto",
        help="progress display (default: a bar on a terminal, else a line every --progress-interval)",
    )
    run.add_argument(
        "--progress-interval", type=float, metavar="S", help="seconds between progress updates (default 5; bar 0.5)"
    )
    run.add_argument(
        "--max-restarts",
        type=int,
        default=5,
        metavar="N",
        help="restarts of one child per minute before giving up (default 5)",
    )
    run.add_argument(
        "--stop-timeout",
        type=float,
        default=5.0,
        metavar="S",
        help="seconds a child gets after SIGTERM before SIGKILL (default 5)",
    )
    run.add_argument(
        "--start-timeout",
        type=float,
        default=60.0,
        metavar="S",
        help="seconds a service waits for those it starts after (the sim for the planner and restrictor) before "
        "starting anyway (default 60)",
    )
    net = parser.add_argument_group("zenoh")
    net.add_argument(
        "--router",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="start a router (default) or use one that runs elsewhere (--no-router)",
    )
    net.add_argument(
        "--router-listen",
        metavar="ENDPOINT",
        help="where the started router listens (default a free port on 127.0.0.1)",
    )
    net.add_argument(
        "--connect", metavar="ENDPOINTS", help=f"with --no-router: the router to use (default {DEFAULT_ROUTER})"
    )
    net.add_argument(
        "--zenoh-config-dir",
        metavar="DIR",
        help="per-role configs from `arroch deploy render --out-dir` (router.json5, <service>.json5, supervisor.json5)",
    )


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "up",
        help="run a router and the services, supervised, with mission progress",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_up_arguments(parser)
    parser.set_defaults(func=run_up)
    from .deployment.cli import register as register_deploy

    register_deploy(sub)
