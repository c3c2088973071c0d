"""The virtual tablet camera while the simulation runs (``arroch sim --camera ...``).

The pybullet scene (:class:`services.sim.world.World`) mirrors the engine only when a frame is
rendered: robot poses, door leaves, objects (carried ones attached to their robot) and the human
are pushed into it just before :meth:`World.render`. The engine itself never touches pybullet,
so a run without a camera pays nothing for it.

Frames are rendered at ``--camera-rate`` frames per *wall* second: a render costs ~0.1 s at
640x480 (NOTES.md), and whoever watches the frames (the AR client, a person) lives in wall time,
so tying frames to sim time would either flood them at high rates or stall the simulation.

``--camera tablet``: the human's tablet, at her position, ``--camera-height`` above the floor,
looking where she faces (toward her door while at her desk, along her walk otherwise), pitched by
``--camera-pitch``. ``--camera X,Y,Z,YAW,PITCH``: a fixed camera (degrees; YAW counter-clockwise
from +x, PITCH > 0 looks up).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class CameraOptions:
    id: str = "tablet"
    follow_human: bool = True
    fixed: tuple[float, float, float, float, float] | None = None  # x, y, z, yaw, pitch (radians)
    rate: float = 2.0  # frames per wall second
    width: int = 640
    height: int = 480
    fov: float = 60.0  # vertical field of view, degrees
    tablet_height: float = 1.3  # m
    tablet_pitch: float = 0.0  # radians


def add_camera_arguments(group: Any) -> None:
    group.add_argument("--camera", metavar="SPEC", help="'tablet' (follows the human) or X,Y,Z,YAW,PITCH (fixed; degrees)")
    group.add_argument("--camera-id", default="tablet", metavar="ID", help="camera id in camera/<id>/frame|truth (default tablet)")
    group.add_argument("--camera-rate", type=float, default=2.0, metavar="HZ", help="frames per wall second (default 2)")
    group.add_argument("--camera-size", default="640x480", metavar="WxH", help="image size (default 640x480)")
    group.add_argument("--camera-fov", type=float, default=60.0, metavar="DEG", help="vertical field of view (default 60)")
    group.add_argument("--camera-height", type=float, default=1.3, metavar="M", help="tablet height above the floor (default 1.3)")
    group.add_argument("--camera-pitch", type=float, default=0.0, metavar="DEG", help="tablet pitch, > 0 looks up (default 0)")


def camera_options_from(args: argparse.Namespace) -> CameraOptions | None:
    """The camera options, or None without ``--camera``. Raises ValueError naming the bad option."""
    spec = getattr(args, "camera", None)
    if not spec:
        return None
    try:
        width, height = (int(v) for v in args.camera_size.lower().split("x"))
    except ValueError:
        raise ValueError(f"--camera-size {args.camera_size!r} is not WxH (e.g. 640x480)") from None
    if not (16 <= width <= 4096 and 16 <= height <= 4096):
        raise ValueError("--camera-size must be between 16x16 and 4096x4096")
    if not 1.0 <= args.camera_fov <= 170.0:
        raise ValueError("--camera-fov must be within [1, 170] degrees")
    if not args.camera_rate > 0:
        raise ValueError("--camera-rate must be > 0")
    common = dict(id=args.camera_id, rate=args.camera_rate, width=width, height=height, fov=args.camera_fov,
                  tablet_height=args.camera_height, tablet_pitch=math.radians(args.camera_pitch))
    if spec == "tablet":
        options = CameraOptions(follow_human=True, **common)
    else:
        try:
            x, y, z, yaw, pitch = (float(v) for v in spec.split(","))
        except ValueError:
            raise ValueError(f"--camera {spec!r} is neither 'tablet' nor X,Y,Z,YAW,PITCH") from None
        options = CameraOptions(follow_human=False, fixed=(x, y, z, math.radians(yaw), math.radians(pitch)), **common)
    camera_spec(options, (0.0, 0.0, 0.0))  # the camera module's own checks (pitch, size), now
    return options


TABLET_REACH = 0.3  # m in front of her body where she holds the tablet


def camera_spec(options: CameraOptions, human_pose: tuple[float, float, float]) -> Any:
    """Where the camera is now: the fixed pose, or the human's tablet in front of her."""
    from .camera import CameraSpec

    size = dict(width=options.width, height=options.height, vfov_deg=options.fov)
    if options.follow_human:
        x, y, yaw = human_pose
        position = (x + TABLET_REACH * math.cos(yaw), y + TABLET_REACH * math.sin(yaw), options.tablet_height)
        return CameraSpec(position, yaw, options.tablet_pitch, **size)
    assert options.fixed is not None
    x, y, z, yaw, pitch = options.fixed
    return CameraSpec((x, y, z), yaw, pitch, **size)


class CameraFeed:
    """Renders the engine's scene for one camera at ``options.rate`` frames per wall second."""

    def __init__(self, site: Any, engine: Any, options: CameraOptions) -> None:
        from .mirror import WorldMirror
        from .world import World  # pybullet: only when a camera is asked for

        self.options = options
        self.engine = engine
        self.world = World(site)
        self.mirror = WorldMirror(self.world, engine)
        self._next = 0.0
        self.frames = 0

    def maybe_render(self, service: Any, wall: float) -> None:
        """Render and publish a frame if one is due (CameraFrame, then its CameraTruth)."""
        if wall < self._next:
            return
        from .camera import frame_message, truth_message

        self._next = wall + 1.0 / self.options.rate
        self.mirror.sync()
        spec = camera_spec(self.options, self.engine.human_pose())
        frame = frame_message(self.options.id, self.world.render(spec), spec)
        service.publish(service.keys.camera_frame(self.options.id), frame)
        service.publish(service.keys.camera_truth(self.options.id), truth_message(self.options.id, spec, frame.seq))
        self.frames += 1

    def close(self) -> None:
        self.world.close()
