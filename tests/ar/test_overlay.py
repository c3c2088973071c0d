"""Overlay primitives and their rasterisation: avatars, intents, doors, X-ray style, clipping,
status, and the Overlay message on the wire."""

from __future__ import annotations

import numpy as np
import pytest

from protocol.codec import decode, encode
from protocol.messages import DoorState, Intent, Overlay, RobotPose, RobotStatus
from runtime.frames import camera_from_yaw_pitch, look_at
from services.ar_client.draw import draw
from services.ar_client.overlay import DOOR_CLOSED, DOOR_OPEN, OverlayBuilder
from services.ar_client.pipeline import BadFrame, Pipeline
from services.ar_client.project import Projector
from services.ar_client.synth import render
from services.ar_client.world import WorldView
from tests.ar.helpers import HD, site

# In the xray site's hall, looking south-west at the wall with door d_a, tilted down a little.
EYE = look_at([5.0, 5.8, 1.4], [2.0, 3.0, 0.3])


def _world(door_open: bool | None = None) -> WorldView:
    w = WorldView()
    w.on_pose(RobotPose(robot="r0", x=3.0, y=5.0, theta=np.pi))  # in the hall: in plain view
    w.on_pose(
        RobotPose(robot="r1", x=1.0, y=3.3, theta=0.0)
    )  # in room a: seen through d_a (line crosses y=4 at x=2.12)
    w.on_status(RobotStatus(robot="r1", state="waiting_at_door"))
    # r0 drives west along the hall, turns south through d_a into room a.
    w.on_intent(
        Intent(
            robot="r0",
            trajectory=[
                [0.0, 3.0, 5.0, np.pi],
                [2.0, 2.0, 5.0, -np.pi / 2],
                [6.0, 2.0, 3.0, -np.pi / 2],
                [22.0, 2.0, 0.6, -np.pi / 2],
            ],
        )
    )
    if door_open is not None:
        w.on_door(DoorState(door="d_a", open=door_open, by="human"))
    return w


def _by_layer(prims):
    out: dict[str, list] = {}
    for p in prims:
        out.setdefault(p.layer, []).append(p)
    return out


def test_visible_and_hidden_robots_and_the_path_through_the_door():
    xray = site("xray")
    builder = OverlayBuilder(xray)
    proj = Projector(EYE, HD)
    closed = _by_layer(builder.world_primitives(proj, _world(False).snapshot(0.0)))
    assert {p.style for p in closed["robot:r0"]} == {"solid"}
    assert {p.style for p in closed["robot:r1"]} == {"xray"}
    assert any(p.kind == "text" and "waiting at door" in p.text for p in closed["robot:r1"])
    assert any(p.kind == "arrow" for p in closed["robot:r0"])  # the heading mark
    # The path: solid in the hall, X-ray beyond the closed door; direction arrows and time marks.
    path = closed["intent:r0"]
    styles = {p.style for p in path if p.kind == "polyline"}
    assert styles == {"solid", "xray"}
    assert sum(p.kind == "arrow" for p in path) >= 3
    assert {p.text for p in path if p.kind == "text"} == {"+10s", "+20s"}
    # The door: red when closed, green when open; with it open r1 is seen through the doorway.
    door = closed["door"]
    assert all(p.color == DOOR_CLOSED for p in door)
    opened = _by_layer(builder.world_primitives(proj, _world(True).snapshot(0.0)))
    assert all(p.color == DOOR_OPEN for p in opened["door"])
    assert {p.style for p in opened["robot:r1"]} == {"solid"}


def test_every_robot_has_its_own_colour_and_label():
    builder = OverlayBuilder(site("hall"))
    w = WorldView()
    for i, rid in enumerate(("r0", "r1", "r9")):  # r9 is not in the site file: it still gets a colour
        w.on_pose(RobotPose(robot=rid, x=4.0 + i, y=5.0, theta=0.0))
    prims = builder.world_primitives(Projector(look_at([8.0, 5.0, 1.5], [4.0, 5.0, 0.3]), HD), w.snapshot(0.0))
    colours = {}
    for p in prims:
        colours.setdefault(p.layer, set()).add(tuple(p.color))
    assert all(len(c) == 1 for c in colours.values())
    assert len({next(iter(colours[f"robot:{r}"])) for r in ("r0", "r1", "r9")}) == 3
    labels = {p.text for p in prims if p.kind == "text"}
    assert labels == {"r0", "r1", "r9"}


def test_robots_behind_and_beside_the_tablet_produce_only_finite_clipped_geometry():
    builder = OverlayBuilder(site("hall"))
    eye = camera_from_yaw_pitch([5.0, 5.0, 1.3], yaw=0.0, pitch=-0.4)  # looking east and down
    w = WorldView()
    w.on_pose(RobotPose(robot="r0", x=3.0, y=5.0, theta=0.0))  # 2 m behind: nothing at all
    w.on_pose(RobotPose(robot="r1", x=5.1, y=5.0, theta=0.0))  # its ring straddles the near plane
    prims = _by_layer(builder.world_primitives(Projector(eye, HD), w.snapshot(0.0)))
    assert "robot:r0" not in prims
    assert prims["robot:r1"]
    for p in prims["robot:r1"]:
        pts = np.asarray(p.points)
        assert np.isfinite(pts).all()
        # Lines grazing the near plane project far off-screen; they are cut to one image size around it.
        assert (pts[:, 0] >= -HD.width).all() and (pts[:, 0] <= 2 * HD.width).all()
        assert (pts[:, 1] >= -HD.height).all() and (pts[:, 1] <= 2 * HD.height).all()


def test_drawn_pixels_carry_the_robot_colour_solid_or_translucent():
    xray = site("xray")
    builder = OverlayBuilder(xray)
    proj = Projector(EYE, HD)
    prims = builder.world_primitives(proj, _world(False).snapshot(0.0))
    grey = np.full((HD.height, HD.width, 3), 100, np.uint8)
    out = draw(grey, prims)
    for rid, solid in (("r0", True), ("r1", False)):
        rgb = np.array(builder.colour(rid)[:3], dtype=float)
        bgr = rgb[::-1]
        expected = bgr if solid else 0.5 * bgr + 0.5 * 100.0  # X-ray: half-transparent over the frame
        ring = np.array(
            [
                [
                    (3.0 if rid == "r0" else 1.0) + 0.25 * np.cos(a),
                    (5.0 if rid == "r0" else 3.3) + 0.25 * np.sin(a),
                    0.45,
                ]
                for a in np.linspace(0, 2 * np.pi, 48)
            ]
        )
        uv, front = proj.project_points(ring)
        hits = 0
        for u, v in np.round(uv[front]).astype(int):
            if 0 <= u < HD.width and 0 <= v < HD.height:
                patch = out[max(v - 1, 0) : v + 2, max(u - 1, 0) : u + 2].reshape(-1, 3).astype(float)
                hits += bool((np.abs(patch - expected).max(axis=1) < 25).any())
        assert hits >= 10, (rid, hits)  # dashed X-ray lines leave gaps, so not every sample hits


def test_without_a_pose_only_the_status_is_drawn_and_it_says_lost():
    hall = site("hall")
    pipeline = Pipeline(hall, _world(False))
    blank = np.full((HD.height, HD.width, 3), 128, np.uint8)
    overlay, image = pipeline.process(blank, HD, 5.0)
    assert not overlay.ok and overlay.position == [] and overlay.quaternion == []
    assert {p.layer for p in overlay.primitives} == {"status"}
    assert "LOST" in overlay.primitives[0].text and "never localised" in overlay.primitives[0].text
    assert image is not None and image.shape == (HD.height, HD.width, 3)


def test_the_pipeline_overlay_travels_on_the_wire_and_bad_frames_raise():
    hall = site("hall")
    w = WorldView()
    w.on_pose(RobotPose(robot="r0", x=2.0, y=5.0, theta=0.0))
    pipeline = Pipeline(hall, w, camera_id="tab")
    truth = look_at([3.5, 5.5, 1.3], [0.05, 5.0, 1.0])
    frame = render(hall, truth, HD)
    import cv2

    ok, jpeg = cv2.imencode(".jpg", frame.image, [cv2.IMWRITE_JPEG_QUALITY, 90])
    overlay, image = pipeline.process(jpeg.tobytes(), HD, 1.0, frame_seq=7)
    assert overlay.ok and overlay.frame_seq == 7 and len(overlay.tags) >= 4
    assert np.linalg.norm(np.array(overlay.position) - truth.position) < 0.01
    back = decode(encode(overlay), Overlay)
    assert back.primitives == overlay.primitives and back.position == overlay.position
    assert any(p.layer == "robot:r0" for p in back.primitives)
    for t in pipeline.timings.__dict__.values():
        assert not isinstance(t, float) or t >= 0.0
    with pytest.raises(BadFrame):
        pipeline.process(b"\xff\xd8 definitely not a jpeg", HD, 2.0)
    with pytest.raises(BadFrame):
        pipeline.process(frame.image[:100], HD, 2.0)  # not the size the intrinsics say


def test_a_frame_is_drawn_with_the_poses_of_its_capture_time_not_later_ones():
    """Poses that came in while a frame waited are newer than its image: the robots drawn are where
    they were when it was captured (the newest pose stamped at or before), so live and replayed
    runs draw the same."""
    w = WorldView()
    for stamp, x in ((0.5, 2.0), (1.0, 2.2), (1.5, 3.0)):
        w.on_pose(RobotPose(robot="r0", x=x, y=5.0, theta=0.0, stamp=stamp))
    assert [w.snapshot(9.0, at=t).robots["r0"].x for t in (0.7, 1.0, 1.2, 0.1)] == [2.0, 2.2, 2.2, 2.0]
    assert w.snapshot(9.0).robots["r0"].x == 3.0  # no capture time: the newest
    w.on_pose(RobotPose(robot="r0", x=9.0, y=5.0, theta=0.0, stamp=0.9))  # overtaken on the wire: ignored
    assert w.snapshot(9.0, at=1.2).robots["r0"].x == 2.2

    hall = site("hall")
    truth = look_at([3.5, 5.5, 1.3], [0.05, 5.0, 1.0])
    image = render(hall, truth, HD).image
    then = WorldView()
    then.on_pose(RobotPose(robot="r0", x=2.2, y=5.0, theta=0.0, stamp=1.0))
    drawn = {}
    for name, view in (("history", w), ("as captured", then)):
        overlay, _ = Pipeline(hall, view, camera_id="tab").process(image, HD, 1.2, frame_seq=1)
        drawn[name] = [p for p in overlay.primitives if p.layer == "robot:r0"]
    assert drawn["history"] and drawn["history"] == drawn["as captured"]
