"""End to end in a real headless Chromium: router + restrictor + ``arroch tablet`` + a test client on
Zenoh. The page's camera is Chromium's fake device playing a video of the simulator's snapshots of
the office site (``services.sim.world.World`` rendering through ``services.sim.camera.CameraSpec``,
what ``arroch sim snapshot`` writes): a tablet panning slowly across the storage room's tagged
wall, every frame's true pose and intrinsics known, the intrinsics given to the server as its
calibration.

Checked: the page gets the camera and connects; overlays come back and are drawn where the robot
really is (screenshot pixels against the robot's position projected through the snapshot's *true*
camera, not the server's estimate);
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
from protocol.messages import DoorState, Feedback, FeedbackAck, Intent, RobotPose
from services.ar_client.overlay import AVATAR_HEIGHT, OverlayBuilder
from services.sim.camera import CameraSpec, frame_message
from tests.conftest import wait_for_message
from tests.procs import restrictor_argv
from tests.tablet.helpers import (
    ROBOT_XY,
    SITE,
    Snapshots,
    fake_camera,
    hfov_deg,
    insecure,
    run,
    snapshot_at,
    snapshots,
    start_tablet,
    write_video,
)

pytestmark = pytest.mark.integration

ROBOT = "r0"
COLOUR = OverlayBuilder(SITE).colour(ROBOT)[:3]  # RGB
#: A tablet in the kitchen facing its south wall (X, Y, Z, YAW, PITCH): no tag in view.
KITCHEN_VIEW = (3.0, 3.0, 1.3, -90.0, -10.0)


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
    rect = browser.evaluate(
        f"(() => {{ const r = document.getElementById('{element}').getBoundingClientRect(); "
        "return [r.x, r.y, r.width, r.height]; })()"
    )
    x, y, bw, bh = rect
    s = min(bw / size[0], bh / size[1])
    return x + (bw - size[0] * s) / 2, y + (bh - size[1] * s) / 2, s


def _colour_hits(image: np.ndarray, points: np.ndarray, colour, radius: int = 3, tolerance: int = 45) -> float:  # noqa: ANN001
    """Fraction of ``points`` with a pixel of ``colour`` within ``radius`` px."""
    hits = 0
    for u, v in points:
        u, v = int(round(u)), int(round(v))
        patch = image[max(v - radius, 0) : v + radius + 1, max(u - radius, 0) : u + radius + 1].astype(int)
        if patch.size and (np.abs(patch - np.array(colour)).max(axis=2) <= tolerance).any():
            hits += 1
    return hits / len(points)


def _on_screen(points: np.ndarray, camera: CameraSpec, box: tuple[float, float, float]) -> np.ndarray:
    """Viewport pixels of world points seen through ``camera``, its picture shown in ``box`` (see _stage_box)."""
    x0, y0, s = box
    return camera.project(points) * s + [x0, y0]


def _drawn_through(image: np.ndarray, shots: Snapshots, box: tuple[float, float, float]) -> CameraSpec:
    """The true camera of the frame whose overlay the screenshot shows: the camera moves, and the overlay
    on screen is the one of whichever frame was last answered, so take the frame that fits it best
    (the avatar moves about 9 px across the whole pan)."""
    return max(shots.cameras, key=lambda camera: _colour_hits(image, _on_screen(_avatar_rim(), camera, box), COLOUR))


def _assert_pictures_lack_the_robot(shots: Snapshots) -> None:
    """The pictures alone never show the robot's colour where its rim projects (the sim's robots are at
    their starts, out of view): whatever the screenshot has there, the page drew."""
    for frame, camera in zip(shots.frames, shots.cameras, strict=True):
        assert _colour_hits(frame, camera.project(_avatar_rim()), COLOUR) == 0.0


def _avatar_rim() -> np.ndarray:
    """World points on the robot avatar's top ring (drawn by the overlay as a polyline)."""
    a = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    x, y = ROBOT_XY
    r = SITE.params.robot_radius
    return np.column_stack([x + r * np.cos(a), y + r * np.sin(a), np.full(len(a), AVATAR_HEIGHT)])


def _feedback_spy(client) -> queue.Queue[Feedback]:  # noqa: ANN001
    """Every Feedback query on Zenoh, seen by a queryable that never answers (the restrictor does)."""
    seen: queue.Queue = queue.Queue()

    def on_query(query) -> None:  # noqa: ANN001
        if query.payload is not None:
            seen.put(decode(query.payload.to_bytes(), Feedback))

    client._declared.append(client.session.declare_queryable(client.keys.feedback(), on_query))
    return seen


def test_ar_page_overlays_where_the_robot_is_and_feedback_round_trips(
    router, namespace, client, spawn, browser, tmp_path
):
    restrictor = spawn(
        restrictor_argv(namespace, router, tmp_path / "restrictor"),
        name="restrictor",
    )
    shots = snapshots()
    _assert_pictures_lack_the_robot(shots)
    video, intrinsics = fake_camera(tmp_path, shots)
    server = start_tablet(spawn, router, namespace, tmp_path / "tablet", "--intrinsics", str(intrinsics))
    restrictor.wait_for("up on namespace", timeout=30)
    feedback_seen = _feedback_spy(client)
    acks = client.collect(client.keys.feedback_ack("*"), FeedbackAck)
    time.sleep(0.5)  # subscriptions meet through the router
    _publish_world(client, time.time())

    page = browser(fake_camera=video, window=(1280, 800))
    page.navigate(server.url)
    state = page.wait_for(
        "window.arroch && window.arroch.state().overlay && window.arroch.state().overlay.ok"
        " && window.arroch.state().overlay.primitives > 0 && window.arroch.state()",
        timeout=40,
    )
    assert state["camera"] == "on" and state["video"] == [shots.intrinsics.width, shots.intrinsics.height]
    assert state["overlay"]["intrinsics"].startswith("calibrated")
    assert len(state["overlay"]["tags"]) >= 4 and state["overlay"]["rmse"] < 1.0
    assert page.evaluate("document.getElementById('pose').textContent").startswith("pose: ")
    assert "ms" in page.evaluate("document.getElementById('link').textContent")

    # The robot's avatar is drawn where the true camera sees it, and not everywhere.
    time.sleep(0.3)
    image = _screen(page)
    assert image.shape[1] == page.evaluate("window.innerWidth")  # one screenshot pixel per CSS pixel
    box = _stage_box(page, "stage", (shots.intrinsics.width, shots.intrinsics.height))
    truth = _drawn_through(image, shots, box)
    rim = _on_screen(_avatar_rim(), truth, box)
    assert _colour_hits(image, rim, COLOUR) >= 0.8, "the avatar's rim is not where the robot is"
    far = _on_screen(
        np.array([[9.6, 0.06, 1.9], [7.0, 0.06, 1.9], [8.3, 0.06, 1.7]]), truth, box
    )  # wall above the tags
    assert _colour_hits(image, far, COLOUR, radius=6) == 0.0
    shifted = rim + [np.ptp(rim[:, 0]) + 20.0, 0.0]  # beside the avatar, clear of it: the check must be able to fail
    assert _colour_hits(image, shifted, COLOUR, radius=2) < 0.2

    # A tap on "I can't open this door for a while" with 30 minutes: a Feedback on Zenoh, an ack on the page.
    page.evaluate(
        "(() => { const s = document.getElementById('param-door_unavailable-minutes'); s.value = '30';"
        " s.dispatchEvent(new Event('change')); })()"
    )
    page.click("#send-door_unavailable")
    sent = feedback_seen.get(timeout=15)
    assert sent.kind == "door_unavailable" and sent.params == {"door": "d_storage", "minutes": 30}
    ack = wait_for_message(acks, lambda a: a.to == sent.src and a.feedback_seq == sent.seq, timeout=15)
    assert ack.accepted and ack.constraint_id
    shown = page.wait_for(
        "(() => { const t = document.getElementById('result-door_unavailable').textContent;"
        " return t.startsWith('accepted') && t; })()",
        timeout=15,
    )
    assert ack.constraint_id in shown
    # The live set reaches the page: the new constraint is listed and becomes the cancel choice.
    page.wait_for(
        f"document.getElementById('active-constraints').textContent.includes('{ack.constraint_id}')", timeout=10
    )
    assert page.evaluate("document.getElementById('param-cancel-constraint_id').value") == ack.constraint_id

    # A wrong token: the page is refused (403), and so is the WebSocket.
    bad = server.url.replace(server.token, "x" * len(server.token))
    page.navigate(bad)
    assert "wrong access token" in page.wait_for(
        "document.body && document.body.innerText.startsWith('403') && document.body.innerText", timeout=10
    )

    async def refused_socket() -> int:
        async with aiohttp.ClientSession(connector=insecure()) as http:
            try:
                async with http.ws_connect(f"{server.base}/ws?token=nope", headers={"Origin": server.base}):
                    return 101
            except aiohttp.WSServerHandshakeError as exc:
                return exc.status

    assert run(refused_socket()) == 403
    assert server.proc.alive() and restrictor.alive()


def _sim_camera(client, shots: Snapshots, stop: threading.Event) -> None:  # noqa: ANN001
    """Publish the snapshots as the sim's camera does (``frame_message``: JPEG and intrinsics), at 5 Hz."""
    messages = [
        frame_message("simcam", frame, camera) for frame, camera in zip(shots.frames, shots.cameras, strict=True)
    ]
    k = 0
    while not stop.is_set():
        client.publish(client.keys.camera_frame("simcam"), messages[k % len(messages)])
        k += 1
        stop.wait(0.2)


def test_viewer_mode_shows_the_sim_stream_with_overlay_and_the_map(router, namespace, client, spawn, browser, tmp_path):
    server = start_tablet(spawn, router, namespace, tmp_path / "tablet", "--camera-source", "sim:simcam")
    assert "mode=viewer" in server.url
    time.sleep(0.5)
    _publish_world(client, time.time())
    shots = snapshots()
    _assert_pictures_lack_the_robot(shots)
    stop = threading.Event()
    feeder = threading.Thread(target=_sim_camera, args=(client, shots, stop), daemon=True)
    feeder.start()
    try:
        page = browser(window=(1280, 800))  # no camera at all
        page.navigate(server.url)
        state = page.wait_for(
            "window.arroch && window.arroch.state().stream_frames > 2 && window.arroch.state().overlay"
            " && window.arroch.state().overlay.ok && window.arroch.state().overlay.primitives > 0"
            " && window.arroch.state()",
            timeout=40,
        )
        assert state["mode"] == "viewer" and state["camera"] == "off" and state["robots"] == [ROBOT]
        time.sleep(0.3)
        image = _screen(page)
        # The stream with its overlay: the avatar where the (sim) camera sees the robot.
        box = _stage_box(page, "stage", (shots.intrinsics.width, shots.intrinsics.height))
        assert _colour_hits(image, _on_screen(_avatar_rim(), _drawn_through(image, shots, box), box), COLOUR) >= 0.8
        # The map: the robot's disc at its position (the page's map transform: fit the site's bounds, 16 px margin).
        mx, my, mw, mh = page.evaluate(
            "(() => { const r = document.getElementById('map').getBoundingClientRect(); return [r.x, r.y, r.width, "
            "r.height]; })()"
        )
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
    """A camera that sees no tag (a sim snapshot of the kitchen's south wall; only the storage room has
    tags): the page says LOST and draws no robot, even though one is published."""
    frame, camera = snapshot_at(KITCHEN_VIEW)
    video = write_video(tmp_path / "kitchen.y4m", [frame, frame])
    # No calibration: the documented default, given the snapshot's horizontal field of view.
    server = start_tablet(spawn, router, namespace, tmp_path / "tablet", "--no-qr", "--fov", f"{hfov_deg(camera):.4f}")
    time.sleep(0.5)
    _publish_world(client, time.time())
    page = browser(fake_camera=video, window=(1280, 800))
    page.navigate(server.url)
    state = page.wait_for("window.arroch && window.arroch.stats().overlays > 5 && window.arroch.state()", timeout=40)
    assert state["overlay"]["ok"] is False and state["overlay"]["primitives"] == 0
    assert "not calibrated" in state["overlay"]["intrinsics"]  # no --intrinsics: the documented default
    pose = page.evaluate("document.getElementById('pose').textContent")
    assert pose.startswith("LOST (no pose yet)"), pose
    image = _screen(page)
    x0, y0, s = _stage_box(page, "stage", (camera.width, camera.height))
    stage = image[int(y0) : int(y0 + camera.height * s), int(x0) : int(x0 + camera.width * s)].astype(int)
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
            sender.inFlight = {
                seq, sent: performance.now() - rtt, captured: performance.now() - rtt - 5, w: 1280, h: 720, bytes: 1,
            };
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
