"""``arroch demo`` (what ``make demo`` runs) end to end: the whole mission with the tablet camera, the
AR client and the tablet page; the page's URL and token printed and the page really served; the run
folder with the metrics, the event log and a few overlay frames that are real drawings over the
camera's images, taken at the sim's held instants (lockstep: a frame every ``--camera-hold`` site
seconds, time held until its overlay came back), so how many are kept does not depend on the load.
With ``--linger`` the page stays up after the mission until Ctrl-C, the metrics printed as a table."""

from __future__ import annotations

import json
import re
import signal
import ssl
import time
import urllib.request
from itertools import pairwise
from pathlib import Path

import cv2
import numpy as np
import pytest

from services.sim.camfeed import CameraOptions
from tests.procs import arroch

pytestmark = [pytest.mark.integration, pytest.mark.slow]

TIMEOUT = 150.0  # wall s; the demo takes 20-35 s on two cores
COLOUR_TOLERANCE = 60.0  # distance in RGB between a drawn pixel and its primitive's colour


def drawn_fraction(image: np.ndarray, primitives: list[dict]) -> tuple[int, float]:
    """(samples, fraction in the primitive's colour) along the solid door and intent lines.

    Neither exists in the camera's image itself (the rendered leaves are blue or brown, the floor
    has no paths), so only drawing puts those colours there; later primitives and the feedback
    panel may cover some of them.
    """
    h, w = image.shape[:2]
    hits = total = 0
    for prim in primitives:
        if (
            prim["kind"] != "polyline"
            or prim["style"] != "solid"
            or not (prim["layer"] == "door" or prim["layer"].startswith("intent:"))
        ):
            continue
        rgb = np.array(prim["color"][:3], dtype=float)
        points = np.asarray(prim["points"], dtype=float)
        for a, b in pairwise(points):
            steps = max(int(np.hypot(*(b - a)) / 3.0), 1)
            for s in np.linspace(0.0, 1.0, steps + 1):
                u, v = np.round(a + s * (b - a)).astype(int)
                if 0 <= u < w and 0 <= v < h:
                    total += 1
                    hits += np.linalg.norm(image[v, u, ::-1].astype(float) - rgb) <= COLOUR_TOLERANCE
    return total, hits / max(total, 1)


def test_demo_runs_the_mission_serves_the_tablet_page_and_keeps_overlay_frames(spawn, tmp_path: Path):
    state = tmp_path / "state"  # the tablet's certificate goes to $XDG_STATE_HOME/arroch/tablet
    proc = spawn(
        arroch("demo", "--run-dir", str(tmp_path / "runs"), "--linger"),
        env={"XDG_STATE_HOME": str(state)},
        name="demo",
    )

    # The URL and the token, said clearly while the mission runs, and the page really there.
    proc.wait_for("==> tablet page", timeout=60)
    token_line = proc.wait_for("access token:", timeout=10)
    token = re.search(r"access token: (\S+)", token_line).group(1)
    url = next(line.strip() for line in proc.output.splitlines() if line.strip().startswith("https://127.0.0.1:"))
    assert f"?token={token}&mode=viewer" in url, url
    context = ssl.create_default_context(cafile=str(state / "arroch" / "tablet" / "ca.pem"))
    with urllib.request.urlopen(url, context=context, timeout=10) as page:
        assert page.status == 200 and b"<html" in page.read().lower()

    # --linger: after the mission, its metrics as a table, and the page still served until Ctrl-C.
    proc.wait_for("stay up until Ctrl-C", timeout=TIMEOUT)
    for row in ("[up] completed ", "[up] human door openings ", "[up] door openings, all ", "the paper's measure"):
        assert row in proc.output, row
    assert re.search(r"\[up\] team completion time +\d+\.\d  s ", proc.output), proc.output[-3000:]
    time.sleep(1.0)
    assert proc.alive()
    with urllib.request.urlopen(url, context=context, timeout=10) as page:
        assert page.status == 200
    proc.signal(signal.SIGINT)  # what a terminal's Ctrl-C sends to the foreground group

    deadline = time.monotonic() + TIMEOUT
    while proc.alive() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not proc.alive(), f"demo not done within {TIMEOUT} s:\n{proc.output[-4000:]}"
    assert proc.popen.returncode == 0, proc.output[-4000:]
    assert "[up] final progress" in proc.output and "delivered 9/9" in proc.output

    (run,) = [p for p in (tmp_path / "runs").iterdir() if p.is_dir()]
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["completed"] is True
    assert sorted(o for r in metrics["robots"].values() for o in r["delivered"]) == [f"o{i}" for i in range(9)]
    kinds = [json.loads(line)["kind"] for line in (run / "events.jsonl").read_text().splitlines()]
    assert kinds.count("mission_done") == 1 and kinds.count("delivered") == 9
    assert (run / "site.png").stat().st_size > 0
    # Recorded by default (tests/recorder/ checks what the recording holds).
    assert (run / "run.mcap").stat().st_size > 100_000 and f"==> recording {run / 'run.mcap'}" in proc.output

    frames = sorted((run / "overlays").glob("overlay-*.png"))
    assert 4 <= len(frames) <= 5, frames  # 5 kept of the ~9 held frames that show a robot and its path
    assert f"{len(frames)} overlay frame(s)" in proc.output
    times, drawn = [], 0
    for frame in frames:
        image = cv2.imread(str(frame))
        assert image is not None and image.shape == (480, 640, 3), frame
        assert image.std() > 20, f"{frame.name} is nearly uniform"
        record = json.loads(frame.with_suffix(".json").read_text())
        layers = {p["layer"] for p in record["primitives"]}
        assert (
            record["ok"]
            and any(layer.startswith("robot:") for layer in layers)
            and any(layer.startswith("intent:") for layer in layers)
        ), layers
        samples, fraction = drawn_fraction(image, record["primitives"])
        # (a frame whose robots and paths are all behind walls has only X-ray lines: none counted)
        assert samples < 20 or fraction >= 0.3, (
            f"{frame.name}: {fraction:.0%} of {samples} points along the drawn lines have their colour"
        )
        drawn += samples >= 20
        times.append(record["time"])
    assert drawn >= 3, f"only {drawn} frames with solid lines drawn"
    # Every one a held frame: drawn at its capture instant, a multiple of the hold interval.
    hold = CameraOptions().hold
    assert all(abs(t - hold * round(t / hold)) < 1e-6 for t in times), times
    # Spread over the mission: from its first minute to the deliveries after the human's first focus
    # interval (the camera shows little else in between: the robots wait behind her door).
    assert times[0] < 60.0 and times[-1] - times[0] > 200.0, times
