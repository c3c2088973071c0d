"""End to end in a real headless Chromium: router + restrictor + ``arroch tablet`` + a test client on
Zenoh. The page's camera is Chromium's fake device playing a video of rendered frames of the office
site from a known pose (the sim's snapshot command is not used: these frames come from
``services.ar_client.synth``, the AR client's renderer of the site's wall tags).

Checked: the page gets the camera and connects; overlays come back and are drawn where the robot
really is (screenshot pixels against the robot's position projected through the *true* camera);
a tap on a feedback button puts a Feedback on Zenoh, the restrictor accepts it and the ack shows
on the page; viewer mode shows the sim's stream with the overlay and the robots on the map; a
wrong token is refused by the page and the WebSocket.
"""

from __future__ import annotations

import queue
import threading
import time

import aiohttp
import cv2
import numpy as np
import pytest

from protocol.codec import decode
from protocol.messages import CameraFrame, DoorState, Feedback, FeedbackAck, Intent, RobotPose
from services.ar_client.overlay import AVATAR_HEIGHT, OverlayBuilder
from tests.conftest import wait_for_message
from tests.procs import arroch
from tests.tablet.helpers import CAMERA, ROBOT_XY, SITE, camera_frames, fake_camera, insecure, project, run, start_tablet

pytestmark = pytest.mark.integration

ROBOT = "r0"
COLOUR = OverlayBuilder(SITE).colour(ROBOT)[:3]  # RGB


def _publish_world(client, now: float) -> None:  # noqa: ANN001
    x, y = ROBOT_XY
    client.publish(client.keys.robot_pose(ROBOT), RobotPose(robot=ROBOT, x=x, y=y, theta=0.0))
    path = [[now + k * 2.0, x + 0.5 * k, y, 0.0] for k in range(5)]
    client.publish(client.keys.intent(ROBOT), Intent(robot=ROBOT, trajectory=path))
    client.publish(client.keys.door_state("d_storage"), DoorState(door="d_storage", open=False))


def _screen(browser) -> np.ndarray:  # noqa: ANN001
    png = browser.screenshot()
    image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    return image[:, :, ::-1]  # RGB


def _stage_box(browser, element: str, size: tuple[int, int]) -> tuple[float, float, float]:  # noqa: ANN001
    """(x, y, scale) of a ``size`` picture shown with object-fit: contain in ``element`` (viewport px)."""
    rect = browser.evaluate(f"(() => {{ const r = document.getElementById('{element}').getBoundingClientRect(); return [r.x, r.y, r.width, r.height]; }})()")
    x, y, bw, bh = rect
    s = min(bw / size[0], bh / size[1])
    return x + (bw - size[0] * s) / 2, y + (bh - size[1] * s) / 2, s


def _colour_hits(image: np.ndarray, points: np.ndarray, colour, radius: int = 3, tolerance: int = 45) -> float:  # noqa: ANN001
    """Fraction of ``points`` with a pixel of ``colour`` within ``radius`` px."""
    hits = 0
    for u, v in points:
        u, v = int(round(u)), int(round(v))
        patch = image[max(v - radius, 0):v + radius + 1, max(u - radius, 0):u + radius + 1].astype(int)
        if patch.size and (np.abs(patch - np.array(colour)).max(axis=2) <= tolerance).any():
            hits += 1
    return hits / len(points)


def _avatar_rim() -> np.ndarray:
    """World points on the robot avatar's top ring (drawn by the overlay as a polyline)."""
    a = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    x, y = ROBOT_XY
    r = SITE.params.robot_radius
    return np.column_stack([x + r * np.cos(a), y + r * np.sin(a), np.full(len(a), AVATAR_HEIGHT)])


def _feedback_spy(client) -> "queue.Queue[Feedback]":  # noqa: ANN001
    """Every Feedback query on Zenoh, seen by a queryable that never answers (the restrictor does)."""
    seen: queue.Queue = queue.Queue()

    def on_query(query) -> None:  # noqa: ANN001
        if query.payload is not None:
            seen.put(decode(query.payload.to_bytes(), Feedback))

    client._declared.append(client.session.declare_queryable(client.keys.feedback(), on_query))
    return seen


def test_ar_page_overlays_where_the_robot_is_and_feedback_round_trips(router, namespace, client, spawn, browser, tmp_path):
    restrictor = spawn(arroch("restrictor", "--namespace", namespace, "--connect", router, "--clock", "wall",
                              "--state-dir", str(tmp_path / "restrictor")), name="restrictor")
    video, intrinsics = fake_camera(tmp_path)
    server = start_tablet(spawn, router, namespace, tmp_path / "tablet", "--intrinsics", str(intrinsics))
    restrictor.wait_for("up on namespace", timeout=30)
    feedback_seen = _feedback_spy(client)
    acks = client.collect(client.keys.feedback_ack("*"), FeedbackAck)
    time.sleep(0.5)  # subscriptions meet through the router
    _publish_world(client, time.time())

    page = browser(fake_camera=video, window=(1280, 800))
    page.navigate(server.url)
    state = page.wait_for("window.arroch && window.arroch.state().overlay && window.arroch.state().overlay.ok"
                          " && window.arroch.state().overlay.primitives > 0 && window.arroch.state()", timeout=40)
    assert state["camera"] == "on" and state["video"] == [CAMERA.width, CAMERA.height]
    assert state["overlay"]["intrinsics"].startswith("calibrated")
    assert len(state["overlay"]["tags"]) >= 4 and state["overlay"]["rmse"] < 1.0
    assert page.evaluate("document.getElementById('pose').textContent").startswith("pose: ")
    assert "ms" in page.evaluate("document.getElementById('link').textContent")

    # The robot's avatar is drawn where the true camera sees it, and not everywhere.
    time.sleep(0.3)
    image = _screen(page)
    assert image.shape[1] == page.evaluate("window.innerWidth")  # one screenshot pixel per CSS pixel
    x0, y0, s = _stage_box(page, "stage", (CAMERA.width, CAMERA.height))
    rim = project(_avatar_rim()) * s + [x0, y0]
    assert _colour_hits(image, rim, COLOUR) >= 0.8, "the avatar's rim is not where the robot is"
    far = project(np.array([[9.6, 0.06, 1.9], [7.0, 0.06, 1.9], [8.3, 0.06, 1.7]])) * s + [x0, y0]  # wall above the tags
    assert _colour_hits(image, far, COLOUR, radius=6) == 0.0
    shifted = rim + [0.0, 40.0]  # 40 px off: the check must be able to fail
    assert _colour_hits(image, shifted, COLOUR, radius=2) < 0.5

    # A tap on "I can't open this door for a while" with 30 minutes: a Feedback on Zenoh, an ack on the page.
    page.evaluate("(() => { const s = document.getElementById('param-door_unavailable-minutes'); s.value = '30';"
                  " s.dispatchEvent(new Event('change')); })()")
    page.click(*page.center_of("#send-door_unavailable"))
    sent = feedback_seen.get(timeout=15)
    assert sent.kind == "door_unavailable" and sent.params == {"door": "d_storage", "minutes": 30}
    ack = wait_for_message(acks, lambda a: a.to == sent.src and a.feedback_seq == sent.seq, timeout=15)
    assert ack.accepted and ack.constraint_id
    shown = page.wait_for("(() => { const t = document.getElementById('result-door_unavailable').textContent;"
                          " return t.startsWith('accepted') && t; })()", timeout=15)
    assert ack.constraint_id in shown
    # The live set reaches the page: the new constraint is listed and becomes the cancel choice.
    page.wait_for(f"document.getElementById('active-constraints').textContent.includes('{ack.constraint_id}')", timeout=10)
    assert page.evaluate("document.getElementById('param-cancel-constraint_id').value") == ack.constraint_id

    # A wrong token: the page is refused (403), and so is the WebSocket.
    bad = server.url.replace(server.token, "x" * len(server.token))
    page.navigate(bad)
    assert "wrong access token" in page.wait_for("document.body && document.body.innerText.startsWith('403') && document.body.innerText", timeout=10)

    async def refused_socket() -> int:
        async with aiohttp.ClientSession(connector=insecure()) as http:
            try:
                async with http.ws_connect(f"{server.base}/ws?token=nope", headers={"Origin": server.base}):
                    return 101
            except aiohttp.WSServerHandshakeError as exc:
                return exc.status

    assert run(refused_socket()) == 403
    assert server.proc.alive() and restrictor.alive()


def _sim_camera(client, stop: threading.Event) -> None:  # noqa: ANN001
    """Publish rendered frames as the sim's camera, at 5 Hz, with their intrinsics."""
    frames = [cv2.imencode(".jpg", f, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes() for f in camera_frames(3)]
    k = 0
    while not stop.is_set():
        jpeg = frames[k % len(frames)]
        client.publish(client.keys.camera_frame("simcam"), CameraFrame(
            camera="simcam", jpeg=jpeg, width=CAMERA.width, height=CAMERA.height,
            intrinsics=[CAMERA.fx, CAMERA.fy, CAMERA.cx, CAMERA.cy]))
        k += 1
        stop.wait(0.2)


def test_viewer_mode_shows_the_sim_stream_with_overlay_and_the_map(router, namespace, client, spawn, browser, tmp_path):
    server = start_tablet(spawn, router, namespace, tmp_path / "tablet", "--camera-source", "sim:simcam")
    assert "mode=viewer" in server.url
    time.sleep(0.5)
    _publish_world(client, time.time())
    stop = threading.Event()
    feeder = threading.Thread(target=_sim_camera, args=(client, stop), daemon=True)
    feeder.start()
    try:
        page = browser(window=(1280, 800))  # no camera at all
        page.navigate(server.url)
        state = page.wait_for("window.arroch && window.arroch.state().stream_frames > 2 && window.arroch.state().overlay"
                              " && window.arroch.state().overlay.ok && window.arroch.state().overlay.primitives > 0"
                              " && window.arroch.state()", timeout=40)
        assert state["mode"] == "viewer" and state["camera"] == "off" and state["robots"] == [ROBOT]
        time.sleep(0.3)
        image = _screen(page)
        # The stream with its overlay: the avatar where the (sim) camera sees the robot.
        x0, y0, s = _stage_box(page, "stage", (CAMERA.width, CAMERA.height))
        assert _colour_hits(image, project(_avatar_rim()) * s + [x0, y0], COLOUR) >= 0.8
        # The map: the robot's disc at its position (the page's map transform: fit the site's bounds, 16 px margin).
        mx, my, mw, mh = page.evaluate("(() => { const r = document.getElementById('map').getBoundingClientRect(); return [r.x, r.y, r.width, r.height]; })()")
        bx0, by0, bx1, by1 = SITE.bounds
        ms = min((mw - 32) / (bx1 - bx0), (mh - 32) / (by1 - by0))
        ox, oy = (mw - (bx1 - bx0) * ms) / 2, (mh - (by1 - by0) * ms) / 2
        centre = np.array([[mx + ox + (ROBOT_XY[0] - bx0) * ms, my + mh - oy - (ROBOT_XY[1] - by0) * ms]])
        assert _colour_hits(image, centre, COLOUR, radius=2) == 1.0
        assert _colour_hits(image, centre + [0.0, 60.0], COLOUR, radius=2) == 0.0
    finally:
        stop.set()
        feeder.join(2)


def test_no_tags_in_view_means_lost_and_nothing_drawn(router, namespace, client, spawn, browser, tmp_path):
    """A camera that sees no tag: the page says LOST and draws no robot, even though one is published."""
    from services.ar_client.web.fakecam import write_y4m

    rng = np.random.default_rng(0)
    blank = [np.clip(120 + rng.normal(0, 3, (CAMERA.height, CAMERA.width, 3)), 0, 255).astype(np.uint8) for _ in range(4)]
    write_y4m(tmp_path / "blank.y4m", blank)
    server = start_tablet(spawn, router, namespace, tmp_path / "tablet", "--no-qr")
    time.sleep(0.5)
    _publish_world(client, time.time())
    page = browser(fake_camera=tmp_path / "blank.y4m", window=(1280, 800))
    page.navigate(server.url)
    state = page.wait_for("window.arroch && window.arroch.stats().overlays > 5 && window.arroch.state()", timeout=40)
    assert state["overlay"]["ok"] is False and state["overlay"]["primitives"] == 0
    assert "not calibrated" in state["overlay"]["intrinsics"]  # no --intrinsics: the documented default
    pose = page.evaluate("document.getElementById('pose').textContent")
    assert pose.startswith("LOST (no pose yet)"), pose
    image = _screen(page)
    x0, y0, s = _stage_box(page, "stage", (CAMERA.width, CAMERA.height))
    stage = image[int(y0):int(y0 + CAMERA.height * s), int(x0):int(x0 + CAMERA.width * s)].astype(int)
    assert not (np.abs(stage - np.array(COLOUR)).max(axis=2) <= 45).any()


def test_frames_shrink_when_round_trips_grow_and_grow_back(router, namespace, spawn, browser, tmp_path):
    """The page's frame-size policy (static/link.js) in Chromium, fed round trips of chosen lengths."""
    server = start_tablet(spawn, router, namespace, tmp_path / "tablet", "--no-qr")
    page = browser(window=(1280, 800))
    page.navigate(server.url + "&mode=viewer")
    page.wait_for("window.arroch && window.arroch.state().connected", timeout=30)
    trace = page.evaluate("""(async () => {
        const { FrameSender } = await import('/static/link.js');
        const sender = new FrameSender(() => null);
        sender.size = [1280, 720];
        const answer = (rtt) => {
            const seq = sender.seq = sender.seq + 1;
            sender.inFlight = { seq, sent: performance.now() - rtt, captured: performance.now() - rtt - 5, w: 1280, h: 720, bytes: 1 };
            sender.lastChange = -1e9;  // as if the last change were long ago
            sender.answered(seq);
            return [sender.scale, sender.quality];
        };
        const out = { slow: [], fast: [] };
        for (let k = 0; k < 12; k++) out.slow.push(answer(400));
        for (let k = 0; k < 30; k++) out.fast.push(answer(20));
        sender.stop();
        return out;
    })()""")
    scales = [s for s, _ in trace["slow"]]
    assert scales[0] < 1.0 and scales == sorted(scales, reverse=True) and scales[-1] < 0.3
    assert trace["slow"][-1][1] == pytest.approx(0.5)  # JPEG quality down to its floor
    assert trace["fast"][-1] == [1, pytest.approx(0.8)]  # a fast link brings full size and quality back
