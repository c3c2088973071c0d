"""``arroch sim snapshot``: one frame of the virtual camera and its ground truth, written to files.

The world is the site at rest (robots at their starts, objects where the file puts them, the human
at her desk facing her door, doors closed unless ``--open`` says otherwise). The truth file holds
``{"position": [x, y, z], "quaternion": [x, y, z, w] of R_world_camera (OpenCV camera axes),
"intrinsics": [fx, fy, cx, cy, w, h]}`` — the intrinsics that make the PNG's pixels a pinhole
camera's (see :mod:`services.sim.camera`), so ``arroch ar localize --intrinsics`` can take them as
they are.

Exit codes: 0 written; 2 bad arguments or input (camera, size, fov, site, door, output path).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from pathlib import Path
from typing import Any

log = logging.getLogger("arroch.sim.snapshot")

EXIT_USAGE = 2


def _camera_pose(text: str) -> tuple[float, float, float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 5 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{text!r} is not X,Y,Z,YAW,PITCH (five numbers; metres, then degrees)")
    return values  # type: ignore[return-value]


def _image_size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not WxH (e.g. 640x480)") from None
    return width, height


def add_snapshot_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Render one frame of the site with the virtual camera (pybullet ER_TINY_RENDERER) and write it as a PNG, "
        "with its ground truth as JSON: position, quaternion (x, y, z, w of R_world_camera, OpenCV camera axes: "
        "x right, y down, z forward) and the pinhole intrinsics [fx, fy, cx, cy, w, h] matching the pixels."
    )
    # SUPPRESS: a --site given before "snapshot" (on "arroch sim") must not be reset by this default.
    parser.add_argument(
        "--site",
        "--config",
        dest="site",
        default=argparse.SUPPRESS,
        metavar="FILE",
        help="site file (TOML); default: the packaged 'office' site",
    )
    parser.add_argument(
        "--camera",
        required=True,
        type=_camera_pose,
        metavar="X,Y,Z,YAW,PITCH",
        help="camera position in metres (world frame: x east, y north, z up) and its direction in DEGREES: "
        "YAW = viewing direction counter-clockwise from +x (0 east, 90 north), PITCH > 0 looks up; no roll "
        "(the same convention as 'arroch sim --camera X,Y,Z,YAW,PITCH'). E.g. 8.0,2.0,1.3,-70,5 (inside storage, "
        "facing its south wall)",
    )
    parser.add_argument(
        "--size", type=_image_size, default=(640, 480), metavar="WxH", help="image size in pixels (default 640x480)"
    )
    parser.add_argument(
        "--fov", type=float, default=60.0, metavar="DEG", help="vertical field of view in degrees (default 60)"
    )
    parser.add_argument(
        "--supersample",
        type=int,
        default=1,
        metavar="S",
        help="render S times larger and average down, anti-aliased (1-4, default 1)",
    )
    parser.add_argument(
        "--open",
        action="append",
        default=[],
        metavar="DOOR",
        help="show DOOR open (repeatable; 'all' opens every door)",
    )
    parser.add_argument("--out", required=True, metavar="F.png", help="the rendered image (PNG)")
    parser.add_argument("--truth", required=True, metavar="T.json", help="the ground truth (JSON)")


def _error(message: str) -> int:
    print(f"arroch sim snapshot: error: {message}", file=sys.stderr)
    return EXIT_USAGE


def _writable(path: str, option: str) -> Path:
    p = Path(path)
    if not p.parent.is_dir():
        raise ValueError(f"{option} {path}: folder {p.parent} does not exist")
    if p.is_dir():
        raise ValueError(f"{option} {path} is a folder")
    return p


def run_snapshot(args: argparse.Namespace) -> int:
    # Heavy imports (pybullet, OpenCV, the site geometry) only once the arguments parsed.
    import cv2

    from protocol.site import load_site

    from .camera import CameraSpec, truth_json
    from .world import World

    x, y, z, yaw, pitch = args.camera
    width, height = args.size
    try:
        camera = CameraSpec.from_degrees(x, y, z, yaw, pitch, width, height, args.fov, args.supersample)
        out = _writable(args.out, "--out")
        if out.suffix.lower() != ".png":
            raise ValueError(f"--out {args.out} must end in .png")
        truth = _writable(args.truth, "--truth")
        site = load_site(getattr(args, "site", None))
    except (ValueError, FileNotFoundError) as exc:
        return _error(str(exc))
    opened = _doors_to_open(site, args.open)
    if isinstance(opened, str):
        return _error(opened)
    if site.room_at(x, y) is None:
        log.warning("camera at (%.2f, %.2f) is in no room of site %r", x, y, site.name)

    with World(site) as world:
        for did in opened:
            world.set_door_opening(did, 1.0)
        image = world.render(camera)
    if not cv2.imwrite(str(out), cv2.cvtColor(image, cv2.COLOR_RGB2BGR)):
        return _error(f"could not write {out}")
    truth.write_text(json.dumps(truth_json(camera), indent=2) + "\n", encoding="utf-8")
    fx, fy, cx, cy, _, _ = camera.intrinsics
    print(f"wrote {out} ({width}x{height}) and {truth}; intrinsics fx={fx:.3f} fy={fy:.3f} cx={cx:.3f} cy={cy:.3f}")
    return 0


def _doors_to_open(site: Any, names: list[str]) -> list[str] | str:
    """The door ids ``--open`` names, or an error message naming the unknown one."""
    if "all" in names:
        return list(site.door_leaves)
    for did in names:
        if did not in site.door_leaves:
            return f"--open {did}: site {site.name!r} has no door {did!r} (doors: {', '.join(site.door_leaves)})"
    return list(names)
