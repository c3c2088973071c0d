"""``arroch record``, ``arroch view``, ``arroch replay`` and ``arroch runs show``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from protocol.runner import add_common_arguments, namespace_from, run_service, zenoh_options

RECORD_HELP = """Record a namespace's messages to one MCAP file, on the site clock.

Default profile (foxglove): every ARROCH message as it travelled (msgpack, /arroch/<key>, what
`arroch replay` publishes again) plus Foxglove channels: /site (3D scene: walls, doors with their
live state, rooms, tags, objects, robots), /tf (world -> robot/<rid>, world -> camera/<cid>),
/paths (each robot's motion plan in its colour), /plan, /constraints, /events, /progress, /metrics
(JSON with JSON Schemas), /camera/<cid>/image|calibration|overlay (the tablet camera, its
calibration, the AR overlay as image annotations) and /log (feedback, acks, events, service logs).
Profile ros2: the same run as ROS 2 messages in a rosbag2 folder (MCAP storage) for ros2 bag / RViz 2.
Open a recording in Foxglove (docs/foxglove-layout.json) or summarise it with `arroch runs show`.
"""


def _build_recorder(args: argparse.Namespace, *, serve: tuple[str, int] | None):
    from protocol.clock import make_clock
    from protocol.keys import Keys
    from protocol.site import load_site

    from .profile import FoxgloveProfile
    from .service import Recorder
    from .sink import FoxgloveSink

    if not 0.0 < args.image_scale <= 1.0:
        raise ValueError(f"--image-scale must be in (0, 1], got {args.image_scale:g}")
    namespace = namespace_from(args)
    keys = Keys(namespace)
    site = load_site(args.site)
    logs = Path(args.logs) if args.logs else None
    out = Path(args.out) if args.out else None
    profiles = []
    if args.profile == "ros2":
        from .ros2 import Ros2Profile  # rosbags: only for this profile

        profiles.append(Ros2Profile(out or Path(time.strftime("recording-%Y%m%d-%H%M%S")), site))
        if serve is not None:
            profiles.append(FoxgloveProfile(FoxgloveSink(None, serve=serve), keys, site, image_scale=args.image_scale))
    elif out is not None or serve is not None:
        metadata = {
            "namespace": namespace,
            "site": site.name,
            "site_source": str(site.source),
            "profile": "foxglove",
            "clock": args.clock,
            "recorded": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        if out is not None and out.suffix != ".mcap":
            raise ValueError(f"--out {out}: a recording is an .mcap file")
        if out is not None and out.exists():
            raise ValueError(f"--out {out}: the file exists already (a recording is never overwritten)")
        if args.image_scale != 1.0:
            metadata["image_scale"] = f"{args.image_scale:g}"
        profile = FoxgloveProfile(
            FoxgloveSink(out, serve=serve, metadata=metadata), keys, site, image_scale=args.image_scale
        )
        profiles.append(profile)
    return Recorder(namespace, zenoh_options(args), profiles, log_file=logs, clock=make_clock(args.clock))


def run_record(args: argparse.Namespace) -> int:
    if args.out is None and args.profile == "foxglove":
        args.out = time.strftime("recording-%Y%m%d-%H%M%S.mcap")
    serve = (args.view_host, args.view_port) if args.view else None
    return run_service(lambda: _build_recorder(args, serve=serve))


def run_view(args: argparse.Namespace) -> int:
    if args.write_layout:
        from .layout import layout_json

        try:
            Path(args.write_layout).write_text(layout_json(), encoding="utf-8")
        except OSError as exc:
            print(
                f"arroch view: cannot write the layout to {args.write_layout}: {exc.strerror or exc}", file=sys.stderr
            )
            return 2
        print(f"Foxglove layout written to {args.write_layout} (Foxglove: Layouts -> Import from file)")
        return 0
    args.profile = "foxglove"
    return run_service(lambda: _build_recorder(args, serve=(args.host, args.port)))


def run_replay(args: argparse.Namespace) -> int:
    from .replay import replay_main

    return replay_main(args)


def run_runs_show(args: argparse.Namespace) -> int:
    from .runs import show_main

    return show_main(args)


def register(sub: argparse._SubParsersAction) -> None:
    record = sub.add_parser(
        "record",
        help="record a run to MCAP (Foxglove channels, or ROS 2 messages)",
        description=RECORD_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_common_arguments(record)
    record.add_argument(
        "--out", metavar="PATH", help="the .mcap file (profile ros2: the bag folder); default recording-<time>"
    )
    record.add_argument(
        "--profile",
        choices=("foxglove", "ros2"),
        default="foxglove",
        help="foxglove (default): ARROCH messages and Foxglove schemas; ros2: ROS 2 CDR messages",
    )
    record.add_argument(
        "--image-scale",
        type=float,
        default=1.0,
        metavar="F",
        help="keep camera frames scaled by F (0 < F <= 1; JPEG re-encoded, calibration and overlay scaled alike; "
        "default 1)",
    )
    record.add_argument(
        "--logs", metavar="FILE", help="also record the lines of this log (arroch up's supervisor.log) as it grows"
    )
    record.add_argument("--view", action="store_true", help="also serve the channels live (Foxglove WebSocket)")
    record.add_argument("--view-host", default="127.0.0.1", help="with --view: address to serve on (default 127.0.0.1)")
    record.add_argument("--view-port", type=int, default=8765, help="with --view: port (default 8765; 0 = any free)")
    record.set_defaults(func=run_record)

    view = sub.add_parser(
        "view",
        help="serve a namespace live to Foxglove (WebSocket), the channels `arroch record` writes",
        description="Serve the channels of `arroch record` live on the Foxglove WebSocket protocol. "
        "In Foxglove: Open connection -> Foxglove WebSocket -> ws://HOST:PORT; "
        "then import the layout docs/foxglove-layout.json.",
    )
    add_common_arguments(view)
    view.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1)")
    view.add_argument("--port", type=int, default=8765, help="port (default 8765; 0 = any free)")
    view.add_argument("--out", metavar="FILE", help="also record to this .mcap file")
    view.add_argument("--logs", metavar="FILE", help="also show the lines of this log as it grows")
    view.add_argument(
        "--image-scale", type=float, default=1.0, metavar="F", help="serve camera frames scaled by F (default 1)"
    )
    view.add_argument(
        "--write-layout",
        metavar="FILE",
        help="write the Foxglove layout (as docs/foxglove-layout.json) to FILE and exit",
    )
    view.set_defaults(func=run_view)

    from . import replay as replay_module
    from .runs import add_runs_arguments

    replay = sub.add_parser(
        "replay",
        help="publish a recording back onto Zenoh (its pace, x rate, or stepped)",
        description=replay_module.__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    replay_module.add_replay_arguments(replay)
    replay.set_defaults(func=run_replay)

    runs = sub.add_parser("runs", help="look at run folders (arroch runs show DIR)")
    runs_sub = runs.add_subparsers(dest="runs_command", metavar="COMMAND")
    show = runs_sub.add_parser("show", help="a run's summary table, its recording's channels and a timeline PNG")
    add_runs_arguments(show)
    show.set_defaults(func=run_runs_show)
