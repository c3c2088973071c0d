"""The virtual tablet camera while the simulation runs (``arroch sim --camera ...``).

The pybullet scene (:class:`services.sim.world.World`) mirrors the engine only when a frame is
rendered: robot poses, door leaves, objects (carried ones attached to their robot) and the human
are pushed into it just before :meth:`World.render`. The engine itself never touches pybullet,
so a run without a camera pays nothing for it.

Frames are rendered at ``--camera-rate`` frames per *wall* second: a render costs ~0.1 s at
640x480 (NOTES.md), and whoever watches the frames (the AR client, a person) lives in wall time,
so tying frames to sim time would either flood them at high rates or stall the simulation.

Lockstep is the exception (:class:`FrameHold`): there site time runs only between the planner's
answers, and then far faster than wall time, so a frame taken at a wall instant is drawn over a
world that has moved on by the time the AR client has localised it. Instead the sim takes its frames
on the site clock. Every ``--camera-hold`` site seconds (30; 0: off) a held frame: at the first tick
at or past each multiple of it, once the plan answering that instant is in (so the robots' paths
drawn are those of that instant), it holds time still until the AR client's Overlay for that frame
(``ar/<cid>/overlay``, same ``frame_seq``) has come back, or ``--camera-hold-timeout`` wall seconds
(5) have passed; the AR client's kept pictures are of these frames, at site times that are the
same for the same mission. Between them, with ``--camera-every S`` (``arroch demo`` asks for 2: 0.5 Hz
of site time), a frame every S site seconds, time not held, so a recording or a page shows the
mission in small steps whatever its speed; whoever draws them takes the robots' poses of the
frame's capture instant (poses too come at a fixed site-time rate). The default is none
(:data:`LOCKSTEP_FRAME_PERIOD`, 0): a render costs ~0.1 s at 640x480 and the AR client and a
recorder each take their turn on every frame, so a ~650 s mission with a frame every 2 s costs about
3.5 times the CPU of one with held frames only (101 s against 29 s, the default mission with an AR
client, measured); a run people watch pays it, a test or a sweep need not. After
:data:`MAX_MISSED` holds in a row get no overlay (no AR client on this camera, or a dead one), the
camera falls back to the wall rate, so such a run loses only that many timeouts; the first overlay
seen again brings the holds back.

Each frame carries gravity in the camera frame as the tablet's accelerometer would measure it (the
truth turned by ``--camera-gravity-noise`` degrees about each axis, default 1; ``--camera-no-gravity``
sends none), which the AR client uses to tell a single tag's two planar poses apart.

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

import numpy as np

LOCKSTEP_FRAME_PERIOD = 0.0  # site s between two frames besides the held ones in lockstep (0: none)
WATCHED_FRAME_PERIOD = 2.0  # what a run people watch asks for (arroch demo): 0.5 Hz of site time, smooth recordings
HOLD_PERIOD = 30.0  # site s between two held frames in lockstep
# Wall s a held frame waits for its overlay. Rendering, sending and localising a frame takes ~0.2 s on
# a quiet machine; 1.5 s (until 2026-11-29) was too little beside the test suite: two holds in a row
# timed out at the end of a demo, and its camera fell back to the wall rate. Without any AR client a
# run loses MAX_MISSED of these once.
HOLD_TIMEOUT = 5.0


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
    hold: float = HOLD_PERIOD  # lockstep: site s between held frames (0: wall-rate frames as elsewhere)
    every: float = LOCKSTEP_FRAME_PERIOD  # lockstep: site s between two frames, held or not (0: held frames only)
    hold_timeout: float = HOLD_TIMEOUT  # wall seconds a held frame waits for its overlay
    gravity_noise: float | None = 1.0  # degrees per axis on the gravity sent with each frame (None: none sent)


def add_camera_arguments(group: Any) -> None:
    group.add_argument(
        "--camera", metavar="SPEC", help="'tablet' (follows the human) or X,Y,Z,YAW,PITCH (fixed; degrees)"
    )
    group.add_argument(
        "--camera-id", default="tablet", metavar="ID", help="camera id in camera/<id>/frame|truth (default tablet)"
    )
    group.add_argument(
        "--camera-rate", type=float, default=2.0, metavar="HZ", help="frames per wall second (default 2)"
    )
    group.add_argument("--camera-size", default="640x480", metavar="WxH", help="image size (default 640x480)")
    group.add_argument(
        "--camera-fov", type=float, default=60.0, metavar="DEG", help="vertical field of view (default 60)"
    )
    group.add_argument(
        "--camera-height", type=float, default=1.3, metavar="M", help="tablet height above the floor (default 1.3)"
    )
    group.add_argument(
        "--camera-pitch", type=float, default=0.0, metavar="DEG", help="tablet pitch, > 0 looks up (default 0)"
    )
    group.add_argument(
        "--camera-hold",
        type=float,
        default=HOLD_PERIOD,
        metavar="S",
        help="lockstep: every S site seconds a frame with time held until the AR client's overlay of it comes back "
        f"(default {HOLD_PERIOD:g}; 0: frames at --camera-rate per wall second instead)",
    )
    group.add_argument(
        "--camera-every",
        type=float,
        default=LOCKSTEP_FRAME_PERIOD,
        metavar="S",
        help="lockstep: a frame every S site seconds besides the held ones, time not held for them, so "
        f"recordings and pages are smooth (default {LOCKSTEP_FRAME_PERIOD:g}: none; arroch demo asks for "
        f"{WATCHED_FRAME_PERIOD:g})",
    )
    group.add_argument(
        "--camera-hold-timeout",
        type=float,
        default=HOLD_TIMEOUT,
        metavar="S",
        help=f"lockstep: wall seconds a held frame waits for its overlay before time goes on "
        f"(default {HOLD_TIMEOUT:g})",
    )
    group.add_argument(
        "--camera-gravity-noise",
        type=float,
        default=1.0,
        metavar="DEG",
        help="each frame carries gravity in the camera frame as an IMU measures it: the truth turned by "
        "N(0, DEG) about each axis (default 1)",
    )
    group.add_argument(
        "--camera-no-gravity", action="store_true", help="send frames without gravity (a camera without an IMU)"
    )


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
    if not (math.isfinite(args.camera_hold) and args.camera_hold >= 0):
        raise ValueError(f"--camera-hold must be >= 0 site seconds (0: no held frames), got {args.camera_hold}")
    every = getattr(args, "camera_every", LOCKSTEP_FRAME_PERIOD)
    if not (math.isfinite(every) and every >= 0):
        raise ValueError(f"--camera-every must be >= 0 site seconds (0: none besides the held frames), got {every}")
    if not (math.isfinite(args.camera_hold_timeout) and args.camera_hold_timeout > 0):
        raise ValueError(f"--camera-hold-timeout must be > 0 wall seconds, got {args.camera_hold_timeout}")
    noise = getattr(args, "camera_gravity_noise", 1.0)
    if not (math.isfinite(noise) and 0.0 <= noise <= 90.0):
        raise ValueError(f"--camera-gravity-noise must be within [0, 90] degrees, got {noise}")
    common = dict(
        id=args.camera_id,
        rate=args.camera_rate,
        width=width,
        height=height,
        fov=args.camera_fov,
        tablet_height=args.camera_height,
        tablet_pitch=math.radians(args.camera_pitch),
        hold=args.camera_hold,
        every=every,
        hold_timeout=args.camera_hold_timeout,
        gravity_noise=None if getattr(args, "camera_no_gravity", False) else getattr(args, "camera_gravity_noise", 1.0),
    )
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


MAX_MISSED = 2  # held frames in a row without an overlay before the camera falls back to the wall rate
_EPS = 1e-6  # site seconds: a tick landing a rounding error short of a hold instant is at it


class FrameHold:
    """When lockstep time waits for a camera frame's overlay (pure: site and wall times passed in).

    Hold instants are the multiples of ``every`` site seconds (0 included): one is due at the first
    tick at or past it. A hold starts (:meth:`begin`), gets its frame's seq (:meth:`framed`) and
    ends with that frame's overlay (:meth:`overlay`) or after ``timeout`` wall seconds
    (:meth:`expired`). ``MAX_MISSED`` timeouts in a row suspend the holds until any overlay is seen.
    """

    def __init__(self, every: float, timeout: float) -> None:
        if not every > 0:
            raise ValueError(f"hold interval must be > 0 site seconds, got {every}")
        if not timeout > 0:
            raise ValueError(f"hold timeout must be > 0 wall seconds, got {timeout}")
        self.every = every
        self.timeout = timeout
        self.next_at = 0.0  # site time of the next hold instant
        self.active = False
        self.seq: int | None = None  # the held frame's seq, once published
        self.started = 0.0  # wall time the hold began
        self.missed = 0  # holds in a row that timed out
        self.held = 0  # holds begun
        self.released = 0  # ended by their overlay
        self.timed_out = 0
        self.render_wall = 0.0  # wall seconds spent rendering held frames
        self.wait_wall = 0.0  # wall seconds from a held frame's publication to its overlay (or timeout)
        self._framed_at = 0.0

    @property
    def suspended(self) -> bool:
        """Too many holds in a row got no overlay: nobody is drawing this camera's frames."""
        return self.missed >= MAX_MISSED

    def due(self, t: float) -> bool:
        return not self.active and t >= self.next_at - _EPS

    def skip(self, t: float) -> None:
        """Let a due instant pass without holding (suspended)."""
        self.next_at = self._after(t)

    def begin(self, t: float, wall: float) -> None:
        self.active, self.seq, self.started = True, None, wall
        self.next_at = self._after(t)
        self.held += 1

    def framed(self, seq: int, wall: float) -> None:
        self.seq = seq
        self._framed_at = wall
        self.render_wall += wall - self.started

    def overlay(self, frame_seq: int, wall: float) -> bool:
        """An overlay of this camera was seen; True when it releases the hold. Any overlay shows
        that an AR client is drawing the frames, so it also ends a suspension."""
        self.missed = 0
        if self.active and self.seq is not None and frame_seq == self.seq:
            self.active = False
            self.released += 1
            self.wait_wall += wall - self._framed_at
            return True
        return False

    def expired(self, wall: float) -> bool:
        """True (and the hold ended) when the held frame waited ``timeout`` wall seconds in vain
        since its publication (its rendering is the sim's own time, not the AR client's)."""
        since = self._framed_at if self.seq is not None else self.started
        if not self.active or wall - since < self.timeout:
            return False
        self.active = False
        self.missed += 1
        self.timed_out += 1
        self.wait_wall += wall - since
        return True

    def summary(self) -> str:
        return (
            f"{self.held} held frames ({self.released} released by their overlay, {self.timed_out} timed out), "
            f"{self.render_wall:.1f} s wall rendering them, {self.wait_wall:.1f} s waiting for overlays"
        )

    def blocker(self) -> str:
        if not self.active:
            return ""
        return f"camera frame {self.seq if self.seq is not None else '(rendering)'} awaiting its overlay"

    def _after(self, t: float) -> float:
        return (math.floor(t / self.every + _EPS) + 1) * self.every


class CameraFeed:
    """Renders the engine's scene for one camera: at ``options.rate`` frames per wall second, or
    in lockstep (``lockstep=True`` and ``options.hold`` > 0) at the held instants of :attr:`hold`."""

    def __init__(self, site: Any, engine: Any, options: CameraOptions, *, lockstep: bool = False) -> None:
        from .mirror import WorldMirror
        from .world import World  # pybullet: only when a camera is asked for

        self.options = options
        self.engine = engine
        self.world = World(site)
        self.mirror = WorldMirror(self.world, engine)
        self.hold = FrameHold(options.hold, options.hold_timeout) if lockstep and options.hold > 0 else None
        self._next = 0.0
        self._next_site = 0.0  # lockstep: site time of the next frame between holds
        self.frames = 0
        self._rng = np.random.default_rng()  # the IMU noise on each frame's gravity

    @property
    def at_wall_rate(self) -> bool:
        """Frames follow the wall clock: no holds, or holds suspended for want of overlays."""
        return self.hold is None or self.hold.suspended

    def maybe_render(self, service: Any, wall: float) -> None:
        """Render and publish a frame if one is due at the wall rate."""
        if self.at_wall_rate and wall >= self._next:
            self.render(service, wall)

    def maybe_render_between_holds(self, service: Any, wall: float) -> None:
        """Lockstep: render and publish a frame (time not held) if one is due on the site clock."""
        if self.options.every > 0 and not self.at_wall_rate and self.engine.time >= self._next_site - _EPS:
            self.render(service, wall)

    def render(self, service: Any, wall: float) -> int:
        """Render and publish a frame now (CameraFrame, then its CameraTruth); returns its seq."""
        from .camera import frame_message, truth_message

        self._next = wall + 1.0 / self.options.rate
        if self.options.every > 0:
            self._next_site = (math.floor(self.engine.time / self.options.every + _EPS) + 1) * self.options.every
        self.mirror.sync()
        spec = camera_spec(self.options, self.engine.human_pose())
        frame = frame_message(
            self.options.id, self.world.render(spec), spec, gravity_noise_deg=self.options.gravity_noise, rng=self._rng
        )
        service.publish(service.keys.camera_frame(self.options.id), frame)
        service.publish(service.keys.camera_truth(self.options.id), truth_message(self.options.id, spec, frame.seq))
        self.frames += 1
        return frame.seq

    def close(self) -> None:
        self.world.close()
