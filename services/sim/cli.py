"""Command line of the simulator: ``arroch sim [options]`` and ``arroch sim snapshot ...``.

``arroch sim`` runs the simulation service until SIGINT/SIGTERM (or, with ``--until-done``, until
the mission is done; exit code 0, or 4 when the experimenter aborted the trial). Bad configuration
(site file, human config, options; ``--human participant`` with ``--mode lockstep``) exits 2 before
any Zenoh session is opened.

``--mode`` here is the clock mode (realtime, rate, lockstep); the Zenoh session mode is
``--zenoh-mode``, as in every command (or env ``ARROCH_ZENOH_MODE``).
"""

from __future__ import annotations

import argparse
import re
from typing import Any

from protocol.schema import ID_REGEX
from runtime.runner import add_common_arguments, run_service
from runtime.transport import options_from

from .human import FOCUS_READINGS, METHODS, HumanConfig
from .pacing import MODES
from .participant import DOOR_MODES, HUMAN_MODES


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "sim",
        help="simulator: robots, doors, the simulated human, virtual tablet camera",
        description=(
            "Simulate the site: robots follow the planner's RobotCommands, doors open and close, the simulated "
            "human works, opens her door and gives feedback (ARROCH). Publishes clock, poses, statuses, door "
            "states, events and, at the end, the mission's metrics (Event mission_done)."
        ),
        conflict_handler="resolve",  # our --mode (clock mode) replaces the deprecated Zenoh --mode
    )
    add_common_arguments(parser)
    run = parser.add_argument_group("simulation")
    run.add_argument(
        "--method", choices=METHODS, default="arroch", help="arroch (default), no-feedback or no-comm (paper §V-A)"
    )
    run.add_argument(
        "--mode", choices=MODES, default=None, help="clock mode: realtime (default), rate (with --rate) or lockstep"
    )
    run.add_argument(
        "--rate",
        type=float,
        metavar="K",
        help="run K times faster than real time (implies --mode rate); with "
        "--mode lockstep, at most K times faster (to watch a mission, or hurt it, as it goes)",
    )
    run.add_argument("--seed", type=int, default=0, help="seed of the run's random numbers (default 0)")
    run.add_argument("--until-done", action="store_true", help="exit (code 0) once mission_done is published")
    run.add_argument(
        "--time-limit",
        type=float,
        metavar="S",
        help="end the mission unfinished after S sim seconds (default 7200; 0: never)",
    )
    run.add_argument("--tick", type=float, metavar="S", help="sim seconds per engine step (default 0.05, i.e. 20 Hz)")
    run.add_argument(
        "--pose-rate", type=float, default=20.0, metavar="HZ", help="pose publication rate in sim time (default 20)"
    )
    run.add_argument(
        "--lockstep-abort",
        type=float,
        default=None,
        metavar="S",
        help="lockstep: wall seconds to wait for the ack of the human's feedback before the run fails "
        "(exit code 3; default 120). Time stands still meanwhile, so the wait never changes the mission",
    )
    run.add_argument("--metrics-out", metavar="FILE.json", help="write the mission's metrics there when it ends")
    run.add_argument("--events-out", metavar="FILE.jsonl", help="write every event there, one JSON line each")
    real = parser.add_argument_group("real robots and ROS 2 bases (docs/ros2.md)")
    real.add_argument(
        "--robots",
        choices=("sim", "none"),
        default="sim",
        help="none: the robots are real, each driven by its own "
        "`arroch robot --ros2`; the simulator keeps doors, objects and the human (default sim)",
    )
    real.add_argument(
        "--ros2-bases",
        action="store_true",
        help="each robot is a simulated ROS 2 mobile base: Twist on cmd_vel in, "
        "Odometry out; `arroch robot --ros2` drives it",
    )
    from runtime.ros2.config import add_ros2_link_arguments

    add_ros2_link_arguments(real)
    study = parser.add_argument_group("study: a participant in place of the simulated human, real doors")
    study.add_argument(
        "--human",
        choices=HUMAN_MODES,
        default="simulated",
        help="simulated (default): the human model plays her; participant: a person does, on her tablet page "
        "(ParticipantAction on participant/action). Needs site time that follows the wall clock: realtime "
        "(default) or rate, never lockstep",
    )
    study.add_argument(
        "--doors",
        choices=DOOR_MODES,
        default="sim",
        help="sim (default): doors are simulated; sensor: the human-operated doors are real and follow their "
        "sensors (DoorState on door/<door>/sensor: a door controller, `arroch ros2 bridge`, the experimenter's "
        "console); goes with --human participant",
    )
    study.add_argument(
        "--participant", metavar="ID", help="with --human participant: take the acts of this participant only"
    )
    study.add_argument(
        "--trial", metavar="ID", help="take the participant's acts and the experimenter's controls of this trial only"
    )
    human = parser.add_argument_group("simulated human")
    human.add_argument(
        "--human-config", metavar="FILE", help="TOML file with the human model's parameters ([human] table; see docs)"
    )
    human.add_argument(
        "--door-probability",
        type=float,
        metavar="P",
        help="chance per waiting robot per decision interval that she goes to open (default 0.5)",
    )
    human.add_argument(
        "--task-mean", type=float, metavar="S", help="mean length of her own task in seconds (default 600)"
    )
    human.add_argument(
        "--interruption-cost",
        type=float,
        metavar="S",
        help="seconds of her task lost each time she leaves it during a focus interval (default 0)",
    )
    human.add_argument(
        "--focus-reading",
        choices=FOCUS_READINGS,
        help="faithful (default): only a declared focus interval keeps her from doors; strict: any focus interval does",
    )
    from .camfeed import add_camera_arguments

    add_camera_arguments(parser.add_argument_group("virtual tablet camera"))
    parser.set_defaults(func=_run)

    from .snapshot import add_snapshot_arguments, run_snapshot

    sub = parser.add_subparsers(dest="sim_command", metavar="SUBCOMMAND")
    snap = sub.add_parser("snapshot", help="render one camera frame of the site and write its ground truth")
    add_snapshot_arguments(snap)
    snap.set_defaults(func=run_snapshot)


def _clock_mode(args: argparse.Namespace) -> tuple[str, float]:
    """The clock mode and its rate: K for rate mode, the cap for lockstep (0: none), 1 for realtime."""
    mode = args.mode or ("rate" if args.rate is not None else "realtime")
    if args.rate is not None and not args.rate > 0:
        raise ValueError(f"--rate must be > 0 (got {args.rate:g})")
    if mode == "rate":
        if args.rate is None:
            raise ValueError("--mode rate needs --rate K with K > 0")
        return mode, args.rate
    if mode == "lockstep":
        return mode, args.rate or 0.0
    if args.rate is not None:
        raise ValueError(f"--rate goes with --mode rate or lockstep, not --mode {mode}")
    return mode, 1.0


def build_options(args: argparse.Namespace) -> Any:
    """SimOptions from the parsed command line (raises ValueError/FileNotFoundError when bad)."""
    from .camfeed import camera_options_from
    from .engine import engine_config_with
    from .service import SimOptions

    mode, rate = _clock_mode(args)
    if args.human == "participant" and mode == "lockstep":
        raise ValueError(
            "--human participant: a person acts in real time, so site time must follow the wall clock: "
            "--mode realtime (the default) or --rate K, not --mode lockstep"
        )
    if args.doors == "sensor" and args.human != "participant":
        raise ValueError("--doors sensor: real doors are opened by a real person: it goes with --human participant")
    if args.participant and args.human != "participant":
        raise ValueError("--participant ID filters a participant's acts: it goes with --human participant")
    if args.participant and not re.match(ID_REGEX, args.participant):
        raise ValueError(f"--participant {args.participant!r} is not an id a ParticipantAction can carry")
    if args.trial and len(args.trial) > 64:
        raise ValueError("--trial: at most 64 characters (a ParticipantAction's trial)")
    ros2_bases = None
    if args.ros2_bases:
        from runtime.ros2.config import ros2_config_from

        if args.robots == "none":
            raise ValueError("--ros2-bases simulates the robots' bases: it cannot go with --robots none")
        ros2_bases = ros2_config_from(args)
    if not args.pose_rate > 0:
        raise ValueError("--pose-rate must be > 0")
    if args.lockstep_abort is not None and not args.lockstep_abort > 0:
        raise ValueError(f"--lockstep-abort must be > 0 wall seconds (got {args.lockstep_abort:g})")
    overrides = {
        "door_probability": args.door_probability,
        "task_mean": args.task_mean,
        "interruption_cost": args.interruption_cost,
        "focus_reading": args.focus_reading,
    }
    human = (
        HumanConfig.from_toml(args.human_config, **overrides)
        if args.human_config
        else HumanConfig(**{k: v for k, v in overrides.items() if v is not None})
    )
    return SimOptions(
        method=args.method,
        mode=mode,
        rate=rate,
        seed=args.seed,
        pose_rate=args.pose_rate,
        until_done=args.until_done,
        metrics_out=args.metrics_out,
        events_out=args.events_out,
        engine=engine_config_with(tick=args.tick, time_limit=args.time_limit),
        human=human,
        camera=camera_options_from(args),
        **({"lockstep_abort": args.lockstep_abort} if args.lockstep_abort is not None else {}),
        robots=args.robots,
        ros2_bases=ros2_bases,
        human_mode=args.human,
        doors=args.doors,
        participant=args.participant or "",
        trial=args.trial or "",
    )


def _run(args: argparse.Namespace) -> int:
    def build() -> Any:
        from protocol.site import load_site

        from .service import SimService

        site = load_site(args.site)
        options = build_options(args)
        return SimService(site, options, options_from(args), namespace=args.namespace)

    return run_service(build)
