"""Shared pieces of the tablet tests: the camera the fake video shows, the server process, HTTPS clients.

The camera pictures are the simulator's snapshots (:class:`services.sim.world.World` rendering
through a :class:`services.sim.camera.CameraSpec`, what ``arroch sim snapshot`` writes): the office
site at rest, its tags on the storage room's walls, the human at her desk. Each frame's truth (pose
and the intrinsics that make its pixels a pinhole camera's) comes with it, and the server is given
those intrinsics as its calibration, so the page assumes the camera the pictures were taken with.
"""

from __future__ import annotations

import asyncio
import math
import re
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import aiohttp
import cv2
import numpy as np

from protocol.site import load_site
from services.ar_client.project import Intrinsics
from services.ar_client.web.fakecam import write_y4m
from services.ar_client.web.intrinsics import write_intrinsics
from services.sim.camera import CameraSpec
from services.sim.world import World
from tests.procs import Proc, arroch

SITE = load_site()  # the packaged office site (what `arroch tablet` serves by default)
#: The tablet in the storage room, 1.3 m up, facing the south wall's tags and slightly down
#: (``--camera X,Y,Z,YAW,PITCH`` of ``arroch sim snapshot``; the human at her desk stands in the left of the view).
VIEW = (8.5, 3.2, 1.3, -94.0, -9.0)
#: The snapshot's vertical field of view (degrees; the sim's default).
VFOV = 60.0
#: The slow pan of the video, per frame: metres east and degrees of yaw (the robot's avatar moves
#: about 1.7 px a frame at 640x480, 25 px/s at 15 frames/s).
PAN_STEP = (0.005, 0.1)
#: Where the test robot stands: between the tablet and the wall, in full view.
ROBOT_XY = (8.0, 1.0)


def tablet_camera(step: int = 0, width: int = 640, height: int = 480) -> CameraSpec:
    """The tablet's camera ``step`` frames into its pan."""
    x, y, z, yaw, pitch = VIEW
    return CameraSpec.from_degrees(x + PAN_STEP[0] * step, y, z, yaw + PAN_STEP[1] * step, pitch, width, height, VFOV)


def intrinsics_of(camera: CameraSpec) -> Intrinsics:
    """The snapshot's intrinsics (no distortion) as the AR client's type."""
    fx, fy, cx, cy, w, h = camera.intrinsics
    return Intrinsics(fx, fy, cx, cy, int(w), int(h))


@dataclass(frozen=True)
class Snapshots:
    """Sim snapshots of a moving camera: RGB frames and the camera (truth) each was rendered through."""

    frames: tuple[np.ndarray, ...]
    cameras: tuple[CameraSpec, ...]

    @property
    def intrinsics(self) -> Intrinsics:
        return intrinsics_of(self.cameras[0])  # a pan changes the pose only


@cache
def snapshots(n: int = 6, width: int = 640, height: int = 480) -> Snapshots:
    """``n`` frames of the tablet's pan, rendered by the simulator (about 0.1 s a frame at 640x480)."""
    cameras = tuple(tablet_camera(k, width, height) for k in range(n))
    with World(SITE) as world:
        frames = tuple(world.render(camera) for camera in cameras)
    for frame in frames:
        frame.setflags(write=False)  # shared by every test through the cache
    return Snapshots(frames, cameras)


def snapshot_at(
    view: tuple[float, float, float, float, float], width: int = 640, height: int = 480
) -> tuple[np.ndarray, CameraSpec]:
    """One RGB sim snapshot from ``view`` (X, Y, Z, YAW, PITCH as in ``arroch sim snapshot --camera``)
    and its camera."""
    camera = CameraSpec.from_degrees(*view, width, height, VFOV)
    with World(SITE) as world:
        return world.render(camera), camera


def write_video(path: Path, frames: tuple[np.ndarray, ...] | list[np.ndarray], fps: int = 15) -> Path:
    """A Y4M video of RGB frames for Chromium's fake camera, played forth and back (Chromium loops the
    file, so the camera sways instead of jumping back to the first frame)."""
    frames = list(frames)
    loop = frames + frames[-2:0:-1]
    write_y4m(path, [cv2.cvtColor(f, cv2.COLOR_RGB2BGR) for f in loop], fps=fps)
    return path


def write_calibration(path: Path, shots: Snapshots) -> Path:
    """The snapshots' intrinsics as an intrinsics file (``arroch tablet --intrinsics``)."""
    write_intrinsics(path, shots.intrinsics)
    return path


def fake_camera(folder: Path, shots: Snapshots | None = None) -> tuple[Path, Path]:
    """A Y4M video of sim snapshots for Chromium's fake camera and the matching intrinsics file."""
    shots = shots or snapshots()
    return write_video(folder / "camera.y4m", shots.frames), write_calibration(folder / "intrinsics.json", shots)


def hfov_deg(camera: CameraSpec) -> float:
    """The camera's horizontal field of view (what ``arroch tablet --fov`` takes)."""
    fx, _, _, _, w, _ = camera.intrinsics
    return math.degrees(2.0 * math.atan(w / (2.0 * fx)))


@dataclass
class Server:
    proc: Proc
    url: str  # the printed page URL, token included
    base: str  # https://127.0.0.1:PORT
    token: str


def start_tablet(
    spawn: Callable[..., Proc], router: str, namespace: str, state_dir: Path, *extra: str, port: int | None = None
) -> Server:
    from runtime.transport import free_tcp_port

    port = port or free_tcp_port()
    proc = spawn(
        arroch(
            "tablet",
            "--namespace",
            namespace,
            "--connect",
            router,
            "--clock",
            "wall",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--state-dir",
            str(state_dir),
            *extra,
        ),
        name="tablet",
    )
    line = proc.wait_for("?token=", timeout=40)
    url = re.search(r"https://\S+", line).group(0)
    token = url.split("token=")[1].split("&")[0]
    return Server(proc=proc, url=url, base=f"https://127.0.0.1:{port}", token=token)


def run(coro) -> Any:  # noqa: ANN001
    """The coroutine run to its end on a thread of its own: while a browser is open, Playwright's sync
    API keeps an event loop running in the test's thread, and asyncio.run refuses to start inside it."""
    with ThreadPoolExecutor(max_workers=1) as pool:
        return pool.submit(asyncio.run, coro).result()


def insecure() -> aiohttp.TCPConnector:
    """A connector that accepts the test server's certificate (the test's own CA is not installed)."""
    return aiohttp.TCPConnector(ssl=False)
