"""Command line of the AR client: ``arroch ar``, ``arroch ar localize``, ``arroch ar render``, ``arroch tags sheet``.

Exit codes: 0 done; 1 ``localize`` found no pose (the JSON says why); 2 bad usage or input
(site, image, intrinsics, state file); 1 also when the service could not start.
"""

from __future__ import annotations

import argparse
import json
import logging
import re
import sys
from pathlib import Path
from typing import Any

from runtime.runner import add_common_arguments, run_service

log = logging.getLogger("arroch.ar")

EXIT_NO_POSE = 1
EXIT_USAGE = 2


def _load_site(path: str | None) -> Any:
    from protocol.site import load_site  # heavy (numpy geometry): load on use

    return load_site(path)


def _error(exc: Exception) -> int:
    print(f"error: {exc}", file=sys.stderr)
    return EXIT_USAGE


def _read_image(path: str):  # noqa: ANN202
    import cv2

    image = cv2.imread(path, cv2.IMREAD_COLOR)
    if image is None:
        raise ValueError(f"cannot read image {path}")
    return image


def _intrinsics_for(args: argparse.Namespace, image) -> Any:  # noqa: ANN001
    from .project import Intrinsics

    K = Intrinsics.parse(args.intrinsics)
    if (K.width, K.height) != (image.shape[1], image.shape[0]):
        raise ValueError(f"--intrinsics say {K.width}x{K.height} but {args.image} is {image.shape[1]}x{image.shape[0]}")
    return K


# --------------------------------------------------------------------------- arroch ar (service)


def _run_service(args: argparse.Namespace) -> int:
    from runtime.clock import make_clock
    from runtime.transport import options_from

    from .project import Intrinsics
    from .service import ArService
    from .snapshots import OverlaySnapshots
    from .sources import parse_source

    def build() -> ArService:
        site = _load_site(args.site)
        spec = parse_source(args.source)
        count = {} if args.snapshot_count is None else {"count": args.snapshot_count}
        snapshots = OverlaySnapshots(args.snapshots, **count) if args.snapshots else None
        return ArService(
            site=site,
            namespace=args.namespace or site.name,
            zenoh_options=options_from(args),
            source=spec,
            camera=args.camera,
            intrinsics=Intrinsics.parse(args.intrinsics) if args.intrinsics else None,
            record=args.record,
            detector=args.detector,
            feedback=not args.no_feedback,
            snapshots=snapshots,
            clock=make_clock(args.clock),
        )

    return run_service(build)


# --------------------------------------------------------------------------- arroch ar localize


def _localize(args: argparse.Namespace) -> int:
    from .detect import TagDetector, to_gray
    from .gravity import parse_gravity
    from .pipeline import Pipeline

    try:
        site = _load_site(args.site)
        image = _read_image(args.image)
        K = _intrinsics_for(args, image)
        gravity = parse_gravity(args.gravity) if args.gravity else None
    except (ValueError, FileNotFoundError) as exc:
        return _error(exc)
    # The same detection and pose steps as the service (guided second pass included).
    pipeline = Pipeline(site, detector=TagDetector(args.detector, known_ids=[lm.tag for lm in site.landmarks]))
    result = pipeline.localize(to_gray(image), K, 0.0, gravity)
    data = result.to_json()
    data.pop("lost_age", None)  # a single image has no history
    if args.json:
        print(json.dumps(data))
    elif result.ok:
        x, y, z = data["position"]
        print(
            f"position {x:.4f} {y:.4f} {z:.4f} m, quaternion {' '.join(f'{v:.5f}' for v in data['quaternion'])}, "
            f"tags {data['tags']}, RMSE {data['reprojection_rmse_px']:.3f} px"
        )
    else:
        print(f"no pose: {result.reason}")
    return 0 if result.ok else EXIT_NO_POSE


# --------------------------------------------------------------------------- arroch ar render


def _render(args: argparse.Namespace) -> int:
    import cv2

    from .pipeline import Pipeline
    from .world import WorldView

    try:
        site = _load_site(args.site)
        image = _read_image(args.image)
        K = _intrinsics_for(args, image)
        try:
            state = json.loads(Path(args.state).read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{args.state}: not JSON ({exc})") from None
        world, now = WorldView.from_state(state)
    except (ValueError, FileNotFoundError) as exc:
        return _error(exc)
    from .detect import TagDetector

    pipeline = Pipeline(site, world, detector=TagDetector(args.detector, known_ids=[lm.tag for lm in site.landmarks]))
    overlay, annotated = pipeline.process(image, K, now)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(args.out, annotated):
        return _error(ValueError(f"cannot write {args.out}"))
    loc = pipeline.last_localization
    if overlay.ok:
        print(
            f"wrote {args.out}: pose from tags {overlay.tags}, RMSE {overlay.reprojection_rmse:.3f} px, "
            f"{len(overlay.primitives)} primitives"
        )
    else:
        print(f"wrote {args.out}: no pose ({loc.reason if loc else 'lost'}); only the status is drawn")
    return 0


# --------------------------------------------------------------------------- arroch tags sheet


MAX_SHEET_DPI = 600  # 33 pages at 600 dpi already take a minute and gigabytes


def _tags_sheet(args: argparse.Namespace) -> int:
    from .tags_sheet import write_sheet

    try:
        if not 50 <= args.dpi <= MAX_SHEET_DPI:
            raise ValueError(f"--dpi must be within [50, {MAX_SHEET_DPI}], got {args.dpi}")
        site = _load_site(args.site)
        files = write_sheet(site, args.out, dpi=args.dpi)
    except (ValueError, FileNotFoundError) as exc:
        return _error(exc)
    print(
        f"wrote {len(site.landmarks)} tag page(s) to "
        f"{', '.join(str(f) for f in files[:3])}{' ...' if len(files) > 3 else ''}"
    )
    return 0


# --------------------------------------------------------------------------- registration


def detector_option(name: str) -> str:
    """``--detector``'s type: a known back end whose library is installed (else a usage error naming the extra)."""
    from .detect import detector_method  # OpenCV: loaded only when a command that detects tags runs

    return detector_method(name)


def _add_detector(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--detector",
        type=detector_option,
        default="opencv",
        metavar="{opencv,apriltag}",
        help="tag detector: OpenCV ArUco + edge-fit corners (default), or the AprilTag 3 library (the arroch[apriltag] "
        "extra)",
    )


def _add_image_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--site", "--config", dest="site", metavar="FILE", help="site file (TOML); default: the packaged 'office' site"
    )
    parser.add_argument("--image", required=True, metavar="IMG", help="camera image (PNG/JPEG)")
    parser.add_argument(
        "--intrinsics", required=True, metavar="fx,fy,cx,cy,w,h", help="camera intrinsics (optionally ,k1,k2,p1,p2,k3)"
    )
    _add_detector(parser)
    parser.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))


def register(sub: argparse._SubParsersAction) -> None:
    from . import __doc__ as package_doc

    ar = sub.add_parser(
        "ar",
        help="AR client: localise the tablet from wall tags, overlay robots and plans, feedback buttons",
        description=package_doc,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_common_arguments(ar)
    ar.add_argument(
        "--source",
        default="sim",
        metavar="SRC",
        help="sim (camera/<cid>/frame over Zenoh, default), video:PATH, device:N or images:DIR",
    )
    ar.add_argument(
        "--camera",
        default="tablet",
        metavar="CID",
        help="camera id: frames on camera/<CID>/frame, overlays on ar/<CID>/overlay (default tablet)",
    )
    ar.add_argument(
        "--intrinsics",
        metavar="fx,fy,cx,cy,w,h",
        help="calibration for video/device/images sources (images: or DIR/intrinsics.json)",
    )
    ar.add_argument("--record", metavar="OUT.mp4", help="also write the annotated frames to this video file")
    ar.add_argument("--no-feedback", action="store_true", help="no feedback buttons")
    ar.add_argument(
        "--snapshots",
        metavar="DIR",
        help="keep a few annotated frames there, spread over the run, as PNG (+ the Overlay "
        "as JSON): frames with a pose, a robot and an intent drawn, whose drawing matches the image",
    )
    ar.add_argument("--snapshot-count", type=int, metavar="N", help="frames kept with --snapshots (default 5)")
    _add_detector(ar)
    ar.set_defaults(func=_run_service)
    ar_sub = ar.add_subparsers(dest="ar_command", metavar="{localize,render}")

    loc = ar_sub.add_parser(
        "localize",
        help="tablet pose from one image, as text or JSON",
        description="Estimate the camera pose of one image from the site's landmark tags. "
        "JSON: {ok, position [x,y,z], quaternion [x,y,z,w] of R_world_camera, tags, reprojection_rmse_px} "
        "or {ok: false, reason}. Exit 1 when there is no pose.",
    )
    _add_image_args(loc)
    loc.add_argument("--json", action="store_true", help="print JSON")
    loc.add_argument(
        "--gravity",
        metavar="GX,GY,GZ",
        help="gravity measured at capture, in the camera frame (OpenCV axes: x right, "
        "y down, z forward; pointing down, any unit): picks a single tag's right planar solution, adds "
        "gravity_error_deg",
    )
    # A gravity vector often starts with a minus (-0.1,9.8,0.2); argparse takes only plain negative
    # numbers for values, anything else starting with '-' for an option. This parser has no option
    # that looks like a number, so a '-' followed by a digit is always a value here.
    loc._negative_number_matcher = re.compile(r"^-\.?\d")
    loc.set_defaults(func=_localize)

    ren = ar_sub.add_parser(
        "render",
        help="draw a given world state over an image",
        description="Localise the image, then draw robots, intents and doors from STATE.json over it. "
        'STATE.json: {"time": t, "poses": {rid: [x, y, theta]}, "intents": {rid: [[t, x, y, theta], ...]}, '
        '"doors": {did: true|false (open)}, "status": {rid: state}} (all optional).',
    )
    _add_image_args(ren)
    ren.add_argument("--state", required=True, metavar="STATE.json", help="world state to draw")
    ren.add_argument("--out", required=True, metavar="OUT.png", help="annotated image to write")
    ren.set_defaults(func=_render)

    tags = sub.add_parser("tags", help="printable landmark tags")
    tags_sub = tags.add_subparsers(dest="tags_command", metavar="{sheet}")
    sheet = tags_sub.add_parser(
        "sheet", help="one page per landmark: the tag at true size, its id, where it goes, which way is up"
    )
    sheet.add_argument(
        "--site", "--config", dest="site", metavar="FILE", help="site file (TOML); default: the packaged 'office' site"
    )
    sheet.add_argument(
        "--out", required=True, metavar="tags.pdf", help="a .pdf file, or a .png name / folder for one PNG per tag"
    )
    sheet.add_argument("--dpi", type=int, default=300, help="PNG resolution (default 300)")
    sheet.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    sheet.set_defaults(func=_tags_sheet)
    tags.set_defaults(func=lambda args: (tags.print_help(), EXIT_USAGE)[1])
