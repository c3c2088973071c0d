"""``arroch record``, ``arroch view``, ``arroch replay``, ``arroch runs show`` and ``arroch runs export``."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from collections.abc import Callable
from pathlib import Path

from runtime.runner import add_common_arguments, namespace_from, run_service, zenoh_options
from runtime.transport import NoRouter, through_local_router

from .rosbag import DEFAULT_DISTRO, DISTROS

log = logging.getLogger("arroch.record")
PROFILES = ("foxglove", "ros2", "foxglove,ros2")

RECORD_HELP = """Record a namespace's messages: log times are the wall clock of the run's start plus site time.

Profile foxglove (default): one MCAP file that Foxglove and Lichtblick read whole. Every ARROCH message
as JSON on /arroch/<key> (with its type's JSON Schema) and, as attachments, the bytes it travelled as
(what `arroch replay` publishes again); and the view of the run: /site (3D scene: walls, doors with
their live state, rooms, tags, objects, robots), /tf (map -> <rid>/base_link, map ->
<cid>/camera_optical_frame), /paths (each robot's motion plan in its colour), /progress, /camera/<cid>/
image|calibration|overlay (the tablet camera, its calibration, the AR overlay) and /log (feedback, acks,
events, service logs). Profile ros2: the run as a ROS 2 bag (rosbag2 folder, MCAP storage) of
--ros-distro, with the topics and frames of `arroch ros2 bridge`; foxglove,ros2: both, the bag in
<out>_ros2/ beside the .mcap. Open a recording in Foxglove (docs/foxglove-layout.json), summarise it
with `arroch runs show`, convert it later with `arroch runs export RUN --ros2 OUT`.

Without --connect and with no Zenoh router on the default endpoint, the recorder is the router there.
"""


def _checked_options(args: argparse.Namespace):
    """The Zenoh options, the recorder becoming the local router when none answers (said in one line)."""

    options, note = through_local_router(zenoh_options(args), become=True)
    if note:
        log.warning("%s (connect the services to it as to `arroch router`)", note)
    return options


def _build_recorder(args: argparse.Namespace, *, serve: tuple[str, int] | None):
    from protocol.keys import Keys
    from protocol.site import load_site
    from runtime.clock import make_clock

    from .profile import FoxgloveProfile
    from .service import Recorder
    from .sink import FoxgloveSink
    from .timebase import Timebase

    if not 0.0 < args.image_scale <= 1.0:
        raise ValueError(f"--image-scale must be in (0, 1], got {args.image_scale:g}")
    kinds = args.profile.split(",")
    namespace = namespace_from(args)
    keys = Keys(namespace)
    site = load_site(args.site)
    logs = Path(args.logs) if args.logs else None
    out = Path(args.out) if args.out else None
    clock = make_clock(args.clock)
    timebase = Timebase(0 if args.clock == "wall" else None)  # wall-clock stamps are Unix times already
    mcap = out if "foxglove" in kinds else None
    if mcap is not None:
        if mcap.suffix != ".mcap":
            raise ValueError(f"--out {mcap}: a recording is an .mcap file")
        if mcap.exists():
            raise ValueError(f"--out {mcap}: the file exists already (a recording is never overwritten)")
    ros2 = None
    if "ros2" in kinds:
        from .ros2 import Ros2Profile  # rosbags: only for this profile

        bag = out.with_name(f"{out.stem}_ros2") if mcap is not None and out is not None else out
        ros2 = Ros2Profile(
            bag or Path(time.strftime("recording-%Y%m%d-%H%M%S")), site, timebase, DISTROS[args.ros_distro], namespace
        )
    profiles = []
    if mcap is not None or serve is not None:
        metadata = {
            "namespace": namespace,
            "site": site.name,
            "site_source": str(site.source),
            "profile": args.profile,
            "clock": args.clock,
            "recorded": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        if args.image_scale != 1.0:
            metadata["image_scale"] = f"{args.image_scale:g}"
        sink = FoxgloveSink(mcap, serve=serve)
        profiles.append(
            FoxgloveProfile(
                sink, keys, site, timebase, image_scale=args.image_scale, metadata=metadata, site_clock=args.clock
            )
        )
    if ros2 is not None:
        profiles.append(ros2)
    try:
        options = _checked_options(args)  # after the checks above (the live view's port too): those are said first
    except NoRouter:
        for profile in profiles:
            profile.abort()  # the live view's server stops; no file was made yet
        raise
    return Recorder(namespace, options, profiles, timebase, log_file=logs, clock=clock)


def _run(build: Callable[[], object]) -> int:
    try:
        return run_service(build)
    except NoRouter as exc:
        log.error("%s", exc)
        return 1


def run_record(args: argparse.Namespace) -> int:
    if args.out is None and "foxglove" in args.profile:
        args.out = time.strftime("recording-%Y%m%d-%H%M%S.mcap")
    serve = (args.view_host, args.view_port) if args.view else None
    return _run(lambda: _build_recorder(args, serve=serve))


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
        print(f"Foxglove layout written to {args.write_layout} (Foxglove or Lichtblick: Layouts -> Import)")
        return 0
    args.profile = "foxglove"
    args.ros_distro = DEFAULT_DISTRO
    return _run(lambda: _build_recorder(args, serve=(args.host, args.port)))


def run_replay(args: argparse.Namespace) -> int:
    from .replay import replay_main

    return replay_main(args)


def run_runs_show(args: argparse.Namespace) -> int:
    from .runs import show_main

    return show_main(args)


def run_runs_export(args: argparse.Namespace) -> int:
    from .export import export_ros2
    from .reading import RecordingError
    from .runs import recording_of

    recording = recording_of(Path(args.run))
    try:
        count = export_ros2(recording, Path(args.ros2), DISTROS[args.ros_distro], args.site)
    except (RecordingError, ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return 2
    print(f"{args.ros2}: ROS 2 bag ({args.ros_distro}) of {count} messages of {recording}")
    return 0


def _add_distro(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--ros-distro",
        choices=tuple(DISTROS),
        default=DEFAULT_DISTRO,
        help=f"the ROS 2 distribution whose rosbag2 reads the bag (metadata version, QoS form; default "
        f"{DEFAULT_DISTRO})",
    )


def register(sub: argparse._SubParsersAction) -> None:
    record = sub.add_parser(
        "record",
        help="record a run to MCAP (Foxglove channels, and/or a ROS 2 bag)",
        description=RECORD_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_common_arguments(record)
    record.add_argument(
        "--out", metavar="PATH", help="the .mcap file (profile ros2: the bag folder); default recording-<time>"
    )
    record.add_argument(
        "--profile",
        choices=PROFILES,
        metavar="|".join(PROFILES),
        default="foxglove",
        help="foxglove (default): ARROCH messages and Foxglove schemas; ros2: a ROS 2 bag; foxglove,ros2: both",
    )
    _add_distro(record)
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
        "In Foxglove or Lichtblick: Open connection -> Foxglove WebSocket -> ws://HOST:PORT; "
        "then import the layout docs/foxglove-layout.json. Without --connect and with no Zenoh router on "
        "the default endpoint, it is the router there.",
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

    runs = sub.add_parser("runs", help="look at run folders (arroch runs show DIR, arroch runs export DIR --ros2 OUT)")
    runs_sub = runs.add_subparsers(dest="runs_command", metavar="COMMAND")
    show = runs_sub.add_parser("show", help="a run's summary table, its recording's channels and a timeline PNG")
    add_runs_arguments(show)
    show.set_defaults(func=run_runs_show)
    export = runs_sub.add_parser(
        "export",
        help="convert a run's recording (run.mcap) to a ROS 2 bag, as `arroch record --profile ros2` writes it",
    )
    export.add_argument("run", metavar="RUN", help="a run folder (runs/<time>/) or a recording (.mcap)")
    export.add_argument("--ros2", metavar="OUT", required=True, help="the bag folder to write (must not exist)")
    _add_distro(export)
    export.add_argument(
        "--site", metavar="FILE", help="the site file, when the one the recording names is not on this machine"
    )
    export.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    export.set_defaults(func=run_runs_export)
