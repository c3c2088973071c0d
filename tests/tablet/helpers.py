"""Shared pieces of the tablet tests: the camera the fake video shows, the server process, HTTPS clients."""

from __future__ import annotations

import asyncio
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import aiohttp
import numpy as np

from protocol.site import load_site
from protocol.frames import CameraPose, look_at
from services.ar_client.project import Intrinsics, Projector
from services.ar_client.synth import render
from services.ar_client.web.fakecam import write_y4m
from services.ar_client.web.intrinsics import default_intrinsics, write_intrinsics
from tests.procs import Proc, arroch

SITE = load_site()  # the packaged office site (what `arroch tablet` serves by default)
#: The tablet in the storage room, 1.3 m up, looking at the south wall's tags and slightly down.
TRUTH: CameraPose = look_at([8.5, 3.2, 1.3], [8.3, 0.05, 0.8])
CAMERA: Intrinsics = default_intrinsics(640, 480)
#: Where the test robot stands: between the tablet and the wall, in full view.
ROBOT_XY = (8.0, 1.0)


def camera_frames(n: int = 6, pose: CameraPose = TRUTH, K: Intrinsics = CAMERA) -> list[np.ndarray]:
    """Rendered frames of the site's tags from ``pose`` (a still camera; sensor noise differs per frame)."""
    return [render(SITE, pose, K, seed=seed).image for seed in range(n)]


def fake_camera(folder: Path, pose: CameraPose = TRUTH, K: Intrinsics = CAMERA, n: int = 6) -> tuple[Path, Path]:
    """A Y4M video for Chromium's fake camera and the matching intrinsics file."""
    video, intrinsics = folder / "camera.y4m", folder / "intrinsics.json"
    write_y4m(video, camera_frames(n, pose, K), fps=15)
    write_intrinsics(intrinsics, K)
    return video, intrinsics


def project(points: np.ndarray, pose: CameraPose = TRUTH, K: Intrinsics = CAMERA) -> np.ndarray:
    """Pixels of world points through the true camera (independent of the server's estimate)."""
    uv, front = Projector(pose, K).project_points(np.asarray(points, dtype=float).reshape(-1, 3))
    assert front.all()
    return uv


@dataclass
class Server:
    proc: Proc
    url: str  # the printed page URL, token included
    base: str  # https://127.0.0.1:PORT
    token: str


def start_tablet(spawn: Callable[..., Proc], router: str, namespace: str, state_dir: Path, *extra: str, port: int | None = None) -> Server:
    from protocol.transport import free_tcp_port

    port = port or free_tcp_port()
    proc = spawn(arroch("tablet", "--namespace", namespace, "--connect", router, "--clock", "wall", "--host", "127.0.0.1",
                        "--port", str(port), "--state-dir", str(state_dir), *extra), name="tablet")
    line = proc.wait_for("?token=", timeout=40)
    url = re.search(r"https://\S+", line).group(0)
    token = url.split("token=")[1].split("&")[0]
    return Server(proc=proc, url=url, base=f"https://127.0.0.1:{port}", token=token)


def run(coro) -> Any:  # noqa: ANN001
    return asyncio.run(coro)


def insecure() -> aiohttp.TCPConnector:
    """A connector that accepts the test server's certificate (the test's own CA is not installed)."""
    return aiohttp.TCPConnector(ssl=False)
