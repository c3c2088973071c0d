"""Command line of the tablet client: ``arroch tablet`` and ``arroch ar calibrate``.

Exit codes: 0 done; 1 the server could not start (Zenoh, port); 2 bad usage or configuration
(site, intrinsics file, study trial file, certificate; for ``calibrate``: pattern, images, too few
views).
"""

from __future__ import annotations

import argparse
import logging
import sys

from runtime.runner import add_common_arguments

from ..cli import detector_option

log = logging.getLogger("arroch.tablet")

EXIT_USAGE = 2

CALIBRATE_HELP = """Camera intrinsics from photos of a calibration pattern, written as an intrinsics file for
'arroch tablet --intrinsics FILE' (and 'arroch ar --source images:DIR' as DIR/intrinsics.json).

Patterns:
  chessboard:COLSxROWS:SQUARE            COLS x ROWS inner corners (a 10x7-square board is 9x6),
                                         squares SQUARE metres wide
  charuco:COLSxROWS:SQUARE:MARKER[:DICT] COLS x ROWS squares, square and marker sizes in metres,
                                         DICT a cv2.aruco dictionary (default 4X4_50)

Take 10-20 photos at the resolution the tablet streams, the board filling a good part of the
image, tilted up to about 45 degrees in different directions and in every part of the image."""


def _camera_source(text: str) -> str | None:
    """``browser`` → None; ``sim:CID`` → CID (validated as a key chunk)."""
    if text == "browser":
        return None
    kind, sep, cid = text.partition(":")
    if kind != "sim" or not sep or not cid:
        raise ValueError(f"--camera-source {text!r}: expected browser or sim:CID")
    from protocol.keys import Keys

    Keys("x").camera_frame(cid)  # raises ValueError for an id that cannot be a key chunk
    return cid


def _run_tablet(args: argparse.Namespace) -> int:
    from protocol.site import load_site
    from runtime.clock import make_clock
    from runtime.transport import options_from

    from .bridge import TabletBridge
    from .intrinsics import DEFAULT_HFOV_DEG, CameraModel, load_intrinsics
    from .process import ListenOptions, run_tablet
    from .server import ServerOptions
    from .study_store import progress_path
    from .study_trial import load_trial

    try:
        trial = load_trial(args.study_trial) if args.study_trial else None
        sim_camera = _camera_source(args.camera_source)
        site = load_site(args.site)
        calibration = load_intrinsics(args.intrinsics) if args.intrinsics else None
        hfov = args.fov if args.fov is not None else DEFAULT_HFOV_DEG
        if not 10.0 <= hfov <= 170.0:
            raise ValueError("--fov must be within [10, 170] degrees")
        if not 0.5 <= args.max_fps <= 60.0:
            raise ValueError("--max-fps must be within [0.5, 60]")
        if not 1 <= args.max_clients <= 64 or not 1 <= args.workers <= 16:
            raise ValueError("--max-clients must be within [1, 64] and --workers within [1, 16]")
        if not 0 <= args.port <= 65535:
            raise ValueError("--port must be within [0, 65535]")
        bridge = TabletBridge(
            namespace=args.namespace or site.name,
            zenoh_options=options_from(args),
            sim_camera=sim_camera,
            clock=make_clock(args.clock),
            study=trial is not None,
        )
    except (ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return EXIT_USAGE
    options = ServerOptions(
        max_fps=args.max_fps,
        max_clients=args.max_clients,
        workers=args.workers,
        detector=args.detector,
        allow_origins=list(args.allow_origin or []),
        default_mode="viewer" if sim_camera else "ar",
        study=trial,
        study_progress=progress_path(args.study_trial) if trial is not None else None,
    )
    if trial is not None:
        log.info(
            "study page for %s, trial %s: condition %s, doors %s, puzzle %dx%d (seed %d), questionnaires %s",
            trial.participant,
            trial.trial,
            trial.condition,
            trial.door_control,
            trial.puzzle.rows,
            trial.puzzle.cols,
            trial.puzzle.seed,
            ", ".join(trial.questionnaires),
        )
        if trial.robots_view == "ar" and sim_camera is None:
            log.warning("condition %s shows the sim's camera: give --camera-source sim:CID", trial.condition)
    listen = ListenOptions(
        host=args.host, port=args.port, public_host=args.public_host, state_dir=args.state_dir, qr=not args.no_qr
    )
    return run_tablet(
        site=site, bridge=bridge, camera_model=CameraModel(calibration, hfov), options=options, listen=listen
    )


def _calibrate(args: argparse.Namespace) -> int:
    from .calibrate import Pattern, calibrate, image_files
    from .intrinsics import write_intrinsics

    try:
        pattern = Pattern.parse(args.pattern)
        files = image_files(args.images)
        result = calibrate(files, pattern, args.model)
        write_intrinsics(
            args.out,
            result.intrinsics,
            rms_px=round(result.rms_px, 4),
            pattern=args.pattern,
            model=args.model,
            images=result.used,
        )
    except (ValueError, FileNotFoundError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    K = result.intrinsics
    for name, why in result.skipped.items():
        print(f"skipped {name}: {why}")
    print(
        f"wrote {args.out}: fx {K.fx:.2f} fy {K.fy:.2f} cx {K.cx:.2f} cy {K.cy:.2f} ({K.width}x{K.height}), "
        f"distortion {' '.join(f'{d:.4f}' for d in K.distortion)}, RMS {result.rms_px:.3f} px from {len(result.used)} "
        "image(s)"
    )
    return 0


def _ar_subparsers(sub: argparse._SubParsersAction) -> argparse._SubParsersAction:
    """The sub-commands of ``arroch ar`` (registered by :mod:`services.ar_client.cli` just before)."""
    ar = sub.choices.get("ar")
    if ar is None:
        raise RuntimeError("services.ar_client.web.cli must be registered after services.ar_client.cli")
    for action in ar._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action
    return ar.add_subparsers(dest="ar_command", metavar="{calibrate}")


def register(sub: argparse._SubParsersAction) -> None:
    from . import __doc__ as package_doc

    tablet = sub.add_parser(
        "tablet",
        help="serve the tablet page: AR over the tablet's camera, feedback buttons, viewer mode",
        description=package_doc,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_common_arguments(tablet)
    tablet.add_argument(
        "--camera-source",
        default="browser",
        metavar="SRC",
        help="browser (default: each page sends its own camera) or sim:CID (the page URL opens the viewer "
        "mode: the sim's camera/<CID>/frame stream with the overlay, and the map)",
    )
    tablet.add_argument("--host", default="0.0.0.0", help="address to listen on (default 0.0.0.0: every interface)")
    tablet.add_argument("--port", type=int, default=8443, help="HTTPS port (default 8443; 0: any free port)")
    tablet.add_argument(
        "--public-host",
        metavar="NAME",
        help="host name or address for the printed URL and QR code (default: this machine's addresses)",
    )
    tablet.add_argument(
        "--state-dir", metavar="DIR", help="where the certificate is kept (default $XDG_STATE_HOME/arroch/tablet)"
    )
    tablet.add_argument(
        "--intrinsics",
        metavar="FILE",
        help="camera calibration from 'arroch ar calibrate' (default: an assumed field of view)",
    )
    tablet.add_argument(
        "--fov", type=float, metavar="DEG", help="horizontal field of view assumed without --intrinsics (default 62)"
    )
    tablet.add_argument(
        "--max-fps", type=float, default=15.0, metavar="HZ", help="frames per second a page may send (default 15)"
    )
    tablet.add_argument("--max-clients", type=int, default=8, metavar="N", help="pages connected at once (default 8)")
    tablet.add_argument("--workers", type=int, default=2, metavar="N", help="frame-processing threads (default 2)")
    tablet.add_argument(
        "--detector",
        type=detector_option,
        default="opencv",
        metavar="{opencv,apriltag}",
        help="tag detector (default opencv; apriltag needs the arroch[apriltag] extra)",
    )
    tablet.add_argument(
        "--allow-origin",
        action="append",
        metavar="ORIGIN",
        help="another origin allowed to open the WebSocket (repeatable)",
    )
    tablet.add_argument("--no-qr", action="store_true", help="print the URLs without the QR code")
    tablet.add_argument(
        "--study-trial",
        metavar="FILE",
        help="serve the study page of this trial (JSON written by the study runner: participant, condition, "
        "puzzle, questionnaires, consent); its progress is kept beside it in <stem>.tablet-progress.json",
    )
    tablet.set_defaults(func=_run_tablet)

    ar_sub = _ar_subparsers(sub)
    cal = ar_sub.add_parser(
        "calibrate",
        help="camera intrinsics from chessboard or ChArUco photos",
        description=CALIBRATE_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cal.add_argument(
        "--images", required=True, metavar="DIR", help="folder of photos of the pattern (PNG/JPEG), all one size"
    )
    cal.add_argument(
        "--pattern", required=True, metavar="SPEC", help="chessboard:9x6:0.025 or charuco:7x5:0.04:0.03[:4X4_50]"
    )
    cal.add_argument(
        "--model",
        default="standard",
        choices=("pinhole", "standard", "full"),
        help="distortion model (default standard: k1 k2 p1 p2)",
    )
    cal.add_argument("--out", required=True, metavar="intrinsics.json", help="file to write")
    cal.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    cal.set_defaults(func=_calibrate)
    if ar_sub.metavar and "calibrate" not in ar_sub.metavar:
        ar_sub.metavar = ar_sub.metavar.rstrip("}") + ",calibrate}"
