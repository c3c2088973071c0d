"""``arroch demo`` (what ``make demo`` runs) end to end: the page's URL and token printed before the
mission starts and the page really served; the whole mission paced (lockstep, at most ``--pace``
times real time) with the tablet camera and the AR client; the run folder with the metrics, the
event log and a few overlay frames that are real drawings over the camera's images, taken at the
sim's held instants (lockstep: a frame every ``--camera-hold`` site seconds, time held until its
overlay came back), so how many are kept does not depend on the load. With ``--linger`` the page
goes on showing the run after the mission (its recording replayed in a loop) until Ctrl-C: a
Chromium opened then sees the camera stream with the robots drawn over it."""

from __future__ import annotations

import json
import re
import signal
import ssl
import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

import cv2
import numpy as np
import pytest

from services.demo import WATCHED_CAMERA_EVERY
from services.recorder.reading import channel_stats
from tests.procs import Proc, arroch
from tests.tablet.browser import Browser, chromium_path

pytestmark = [pytest.mark.integration, pytest.mark.slow(seconds=90)]  # wall s on two quiet cores

TIMEOUT = 600.0  # wall s; the demo at --pace 30 takes about a minute on two idle cores, minutes on busy ones
PACE = 30.0  # the test's pace (the default, 10, takes a minute more; the pacing is the same code)
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


@dataclass
class Demo:
    proc: Proc
    url: str
    context: ssl.SSLContext
    runs: Path
    mission_wall: float  # wall s from the mission's start to the end of its run


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Demo]:
    """One ``arroch demo --linger`` run, lingering once its mission is over (the tests below end it)."""
    tmp = tmp_path_factory.mktemp("demo")
    state = tmp / "state"  # the tablet's certificate goes to $XDG_STATE_HOME/arroch/tablet
    proc = Proc(
        arroch("demo", "--run-dir", str(tmp / "runs"), "--linger", "--pace", f"{PACE:g}"),
        env={"XDG_STATE_HOME": str(state)},
        name="demo",
    )
    try:
        # The URL and the token, said clearly before the mission starts, and the page really there.
        proc.wait_for("==> tablet page", timeout=60)
        token_line = proc.wait_for("access token:", timeout=10)
        token = re.search(r"access token: (\S+)", token_line).group(1)
        out = proc.output
        url = next(line.strip() for line in out.splitlines() if line.strip().startswith("https://127.0.0.1:"))
        assert f"?token={token}&mode=viewer" in url, url
        assert "==> running one mission" not in out.split("==> tablet page")[0], out
        context = ssl.create_default_context(cafile=str(state / "arroch" / "tablet" / "ca.pem"))
        with urllib.request.urlopen(url, context=context, timeout=10) as page:
            assert page.status == 200 and b"<html" in page.read().lower()
        mission = proc.wait_for("==> running one mission", timeout=30)
        assert f"lockstep, at most {PACE:g}x real time" in mission, mission
        started = time.monotonic()
        proc.wait_for("==> done; metrics", timeout=TIMEOUT)
        mission_wall = time.monotonic() - started
        proc.wait_for("the page replays its recording in a loop until Ctrl-C", timeout=30)
        yield Demo(proc, url, context, tmp / "runs", mission_wall)
    finally:
        proc.stop()


def _robots_drawn(page: Browser) -> list[dict]:
    """The overlays the page received that draw a robot over a localised camera frame (its WebSocket
    traffic, as the browser reports it; the page draws what it receives)."""
    found = []
    for text in list(page.ws_frames_received):
        if '"overlay"' not in text[:200]:
            continue
        message = json.loads(text)
        if message.get("ok") and any(p["l"].startswith("robot:") for p in message.get("primitives", [])):
            found.append(message)
    return found


def test_after_the_mission_the_page_shows_the_robots_over_the_replayed_camera(demo: Demo):
    if chromium_path() is None:
        pytest.skip("no Chromium on this machine (sudo apt-get install chromium)")
    with Browser(window=(1280, 800)) as page:
        page.navigate(demo.url)
        state = page.wait_for(
            "window.arroch && window.arroch.state().stream_frames > 5 && window.arroch.state().overlay"
            " && window.arroch.state().overlay.ok && window.arroch.state()",
            timeout=60,
        )
        assert state["mode"] == "viewer" and sorted(state["robots"]) == ["r0", "r1", "r2"], state
        deadline = time.monotonic() + 60
        while not _robots_drawn(page) and time.monotonic() < deadline:
            page.pause(0.5)
        assert page.ws_frames_received, "the browser reported none of the page's WebSocket traffic"
        assert _robots_drawn(page), "no overlay with a robot drawn on the camera image reached the page"
        # Drawn on screen: the overlay canvas over the stream has the robots' pixels.
        painted = page.wait_for(
            "(() => { const c = document.getElementById('overlay'); const d = c.getContext('2d')"
            ".getImageData(0, 0, c.width, c.height).data; let n = 0; for (let i = 3; i < d.length; i += 4)"
            " n += d[i] > 0; return n > 500 && n; })()",
            timeout=30,
        )
        assert painted > 500
    assert demo.proc.alive()


def test_demo_runs_the_mission_serves_the_tablet_page_and_keeps_overlay_frames(demo: Demo):
    proc = demo.proc
    for row in ("[up] completed ", "[up] human door openings ", "[up] door openings, all ", "the paper's measure"):
        assert row in proc.output, row
    assert re.search(r"\[up\] team completion time +\d+\.\d  s ", proc.output), proc.output[-3000:]
    with urllib.request.urlopen(demo.url, context=demo.context, timeout=10) as page:
        assert page.status == 200  # still served while lingering
    proc.signal(signal.SIGINT)  # what a terminal's Ctrl-C sends to the foreground group

    deadline = time.monotonic() + TIMEOUT
    while proc.alive() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not proc.alive(), f"demo not done within {TIMEOUT} s:\n{proc.output[-4000:]}"
    assert proc.popen.returncode == 0, proc.output[-4000:]
    assert "[up] final progress" in proc.output and "delivered 9/9" in proc.output

    (run,) = [p for p in demo.runs.iterdir() if p.is_dir()]
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["completed"] is True
    assert sorted(o for r in metrics["robots"].values() for o in r["delivered"]) == [f"o{i}" for i in range(9)]
    kinds = [json.loads(line)["kind"] for line in (run / "events.jsonl").read_text().splitlines()]
    assert kinds.count("mission_done") == 1 and kinds.count("delivered") == 9
    assert (run / "site.png").stat().st_size > 0
    # Recorded by default (tests/recorder/ checks what the recording holds).
    assert (run / "run.mcap").stat().st_size > 100_000 and f"==> recording {run / 'run.mcap'}" in proc.output
    # Camera frames at 0.5 Hz of site time (lockstep: one every 2 site s, held or not) and robot poses
    # at 10 Hz or more, however fast the mission ran: a smooth recording.
    stats = {c.topic: c for c in channel_stats(run / "run.mcap")}
    frames_channel = stats["/camera/tablet/image"]
    assert frames_channel.messages >= 0.5 * (frames_channel.last - frames_channel.first), frames_channel
    poses = stats["/arroch/robot/r0/pose"]
    assert poses.messages >= 10 * (poses.last - poses.first), poses
    # Paced: site time went no faster than PACE times real time (the lockstep cap the demo passed on).
    assert metrics["team_completion_time"] / PACE <= demo.mission_wall, (metrics["team_completion_time"], demo)

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
    # Every one a frame taken on the site clock (held or not): at a multiple of the frame interval.
    every = WATCHED_CAMERA_EVERY  # what the demo asks for (--camera-every)
    camera_lines = [line for line in proc.output.splitlines() if "held frames" in line or "got no overlay" in line]
    assert all(abs(t - every * round(t / every)) < 1e-6 for t in times), (times, camera_lines)
    # Spread over the mission: from its first minute to the deliveries after the human's first focus
    # interval (the camera shows little else in between: the robots wait behind her door).
    assert times[0] < 60.0 and times[-1] - times[0] > 200.0, times
