"""The virtual camera: its pose and intrinsics describe the pixels pybullet renders.

Everything here runs on real rendered pixels (ER_TINY_RENDERER) and real detectors: OpenCV's ArUco
detector (DICT_APRILTAG_36h11) and AprilTag 3 (pupil-apriltags, the reference for corner accuracy).
Corners are put in the site's TL, TR, BR, BL order by runtime/apriltag.py's helpers only.

Measured on these views (default office site, inside storage, tags 0.16 m at 1.4–2.8 m, oblique to
the wall): OpenCV ArUco + CORNER_REFINE_SUBPIX, SQPnP + LM over all tags, 1.3–4.9 mm / 0.04–0.14° at
1280×720 and 2.5–17 mm / 0.09–0.48° at 640×480; AprilTag 3 corners within 1 px of the projected
site corners, mean offset ~0.1 px; rendered tag edges exactly where the intrinsics put them.
The pose thresholds leave room for detector noise; the half-pixel offset of the principal point is
pinned by the edge and corner-offset tests.
"""

from __future__ import annotations

import json
import math
import subprocess
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pybullet
import pytest

from protocol.codec import decode, encode
from protocol.messages import CameraFrame, CameraTruth
from protocol.site import load_site
from protocol.site.model import Site
from runtime.apriltag import apriltag_corners, opencv_corners
from runtime.frames import matrix_from_quat, rotation_angle
from services.ar_client.detect import apriltag_detector
from services.cli import main
from services.sim.camera import FAR, NEAR, CameraSpec, frame_message, truth_json, truth_message
from services.sim.world import World
from tests.procs import ROOT, arroch

# Views from inside storage (x 6..11, y 0..4) at tablet height, oblique to the walls they face,
# clear of the human at her desk: (x, y, z, yaw°, pitch°).
SOUTH_OBLIQUE = (8.0, 2.0, 1.3, -70.0, 5.0)
NORTH_WALL = (8.2, 1.2, 1.25, 100.0, 4.0)
WEST_WALL = (7.5, 2.0, 1.4, 180.0, -5.0)


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site(None)


@pytest.fixture(scope="module")
def world(site: Site) -> Iterator[World]:
    with World(site) as w:
        yield w


@pytest.fixture(scope="module")
def aruco() -> cv2.aruco.ArucoDetector:
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11), params)


def _gray(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)


def _detect_opencv(detector: cv2.aruco.ArucoDetector, gray: np.ndarray) -> dict[int, np.ndarray]:
    corners, ids, _ = detector.detectMarkers(gray)
    return {} if ids is None else {int(i): opencv_corners(c) for c, i in zip(corners, ids.ravel(), strict=True)}


def _detect_apriltag(gray: np.ndarray) -> dict[int, np.ndarray]:
    return {d.tag_id: apriltag_corners(d.corners) for d in apriltag_detector().detect(gray)}


def _tags_in_view(world: World, camera: CameraSpec, *, whole_quad: bool, margin: float = 4.0) -> set[int]:
    """Tags facing the camera with no wall in between and, in the image (``margin`` px inside), their
    whole printed quad (``whole_quad``: a detector must find them) or at least their black square
    (a detector may find them)."""
    out = set()
    eye = np.asarray(camera.position)
    for lm in world.site.landmarks:
        if np.dot(eye - np.asarray(lm.position), lm.normal) <= 0.05:
            continue
        points = world.landmark_quad(lm.tag) if whole_quad else world.landmark_corners(lm.tag)
        if np.any((points - eye) @ camera.R_world_camera[:, 2] <= NEAR):
            continue
        uv = camera.project(points)
        if (
            uv.min() < margin
            or np.any(uv[:, 0] > camera.width - 1 - margin)
            or np.any(uv[:, 1] > camera.height - 1 - margin)
        ):
            continue
        if world.ray(eye, lm.position) is None:  # walls have collision shapes, tags do not
            out.add(lm.tag)
    return out


def _pose_error(site: Site, camera: CameraSpec, found: dict[int, np.ndarray], K: np.ndarray) -> tuple[float, float]:
    """(position error m, rotation error °) of SQPnP + LM over every found tag's corners."""
    by_tag = {lm.tag: lm for lm in site.landmarks}
    obj = np.concatenate([by_tag[t].corners() for t in sorted(found)])
    img = np.concatenate([found[t] for t in sorted(found)])
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, None, flags=cv2.SOLVEPNP_SQPNP)
    assert ok
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, None, rvec, tvec)
    R_cw, _ = cv2.Rodrigues(rvec)
    position = -R_cw.T @ tvec.reshape(3)
    return float(np.linalg.norm(position - np.asarray(camera.position))), math.degrees(
        rotation_angle(R_cw.T, camera.R_world_camera)
    )


# ---------------------------------------------------------------------- geometry of the spec


def test_axes_follow_yaw_and_pitch() -> None:
    level = CameraSpec((0.0, 0.0, 1.0), 0.0, 0.0)
    # OpenCV axes of a level camera looking east: x right = south, y down, z forward = east.
    np.testing.assert_allclose(level.R_world_camera, [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-12)
    up_north = CameraSpec((0.0, 0.0, 1.0), math.pi / 2, math.radians(30.0))
    np.testing.assert_allclose(up_north.R_world_camera[:, 2], [0.0, math.cos(math.radians(30)), 0.5], atol=1e-12)
    assert up_north.R_world_camera[2, 0] == pytest.approx(0.0)  # no roll: image x stays horizontal
    for cam in (level, up_north, CameraSpec((1, 2, 3), 2.5, -0.7)):
        R = cam.R_world_camera
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_allclose(matrix_from_quat(cam.quaternion), R, atol=1e-12)
        T = cam.T_world_camera
        np.testing.assert_allclose(T[:3, :3], R)
        np.testing.assert_allclose(T[:3, 3], cam.position)


def test_intrinsics_and_projection() -> None:
    cam = CameraSpec((0.0, 0.0, 1.0), 0.3, 0.1, 640, 480, 60.0)
    fx, fy, cx, cy, w, h = cam.intrinsics
    assert fx == fy == pytest.approx(480 / (2 * math.tan(math.radians(30))))
    assert (cx, cy, w, h) == (320.0, 239.0, 640.0, 480.0)
    ahead = np.asarray(cam.position) + 3.0 * cam.R_world_camera[:, 2]
    np.testing.assert_allclose(cam.project([ahead]), [[cx, cy]], atol=1e-9)
    with pytest.raises(ValueError, match="behind"):
        cam.project([np.asarray(cam.position) - cam.R_world_camera[:, 2]])
    # Supersampling keeps the pinhole of the averaged-down image (see camera.intrinsics).
    s2 = CameraSpec((0.0, 0.0, 1.0), 0.3, 0.1, 640, 480, 60.0, supersample=2)
    assert s2.intrinsics[:4] == pytest.approx([fx, fy, 320.0 - 0.25, 240.0 - 0.75])
    assert s2.render_size == (1280, 960)


def test_gl_matrices_are_pybullets_own() -> None:
    cam = CameraSpec((8.0, 2.0, 1.3), math.radians(-70), math.radians(5), 1280, 720, 60.0)
    eye = np.asarray(cam.position)
    expected_view = pybullet.computeViewMatrix(
        eye.tolist(), (eye + cam.R_world_camera[:, 2]).tolist(), (-cam.R_world_camera[:, 1]).tolist()
    )
    np.testing.assert_allclose(cam.view_matrix(), expected_view, atol=1e-5)  # pybullet computes in float32
    expected_proj = pybullet.computeProjectionMatrixFOV(60.0, 1280 / 720, NEAR, FAR)
    np.testing.assert_allclose(cam.projection_matrix(), expected_proj, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(pitch=math.radians(90)), "pitch"),
        (dict(width=8), "width"),
        (dict(height=640.5), "height"),
        (dict(vfov_deg=0.0), "field of view"),
        (dict(supersample=5), "supersample"),
        (dict(position=(0.0, float("nan"), 1.0)), "finite"),
        (dict(width=2048, supersample=3), "exceeds"),
    ],
)
def test_bad_cameras_are_refused(kwargs: dict, message: str) -> None:
    args = dict(position=(0.0, 0.0, 1.0), yaw=0.0, pitch=0.0, width=640, height=480, vfov_deg=60.0) | kwargs
    with pytest.raises(ValueError, match=message):
        CameraSpec(**args)


# ---------------------------------------------------------------------- pixels vs pinhole


def _black_runs(world: World, camera: CameraSpec, tag: int, cx: float, cy: float) -> tuple[bool, bool]:
    """Does the rendered black frame of ``tag`` start and end where a pinhole with (cx, cy) puts it?

    The renderer has no anti-aliasing: a pixel is black exactly when its sample point falls inside
    the black square. So along a row through the frame's top module, the black run must span the
    pixel columns ``ceil(u_left) .. floor(u_right)``; likewise down a column for rows. No detector
    is involved: this pins the principal point to a fraction of a pixel.
    """
    gray = _gray(world.render(camera))
    K = camera.K.copy()
    K[0, 2], K[1, 2] = cx, cy
    pc = (world.landmark_corners(tag) - np.asarray(camera.position)) @ camera.R_world_camera
    uv = pc @ K.T
    uv = uv[:, :2] / uv[:, 2:]
    (u_left, v_top), (u_right, _), (_, v_bottom) = uv[0], uv[1], uv[2]
    module = (v_bottom - v_top) / 8
    row, col = int(round(v_top + module / 2)), int(round(u_left + module / 2))
    u0, v0 = int(u_left) - 4, int(v_top) - 4
    run_u = np.flatnonzero(gray[row, u0 : int(u_right) + 5] < 60) + u0
    run_v = np.flatnonzero(gray[v0 : int(v_bottom) + 5, col] < 60) + v0
    return (
        (run_u[0], run_u[-1]) == (math.ceil(u_left), math.floor(u_right)),
        (run_v[0], run_v[-1]) == (math.ceil(v_top), math.floor(v_bottom)),
    )


@pytest.mark.parametrize("size, shots", [((640, 480), 16), ((1280, 720), 6)])
def test_principal_point_matches_rendered_edges(world: World, size: tuple[int, int], shots: int) -> None:
    """Frontal views of tag 4 moved by sub-pixel steps: the edges land where the intrinsics say."""
    w, h = size
    ours = ideal = 0
    for k in range(shots):
        # Steps of ~0.2-0.3 px in both directions, so every sub-pixel phase of the edges occurs.
        cam = CameraSpec.from_degrees(8.23 + k * 0.0011, 1.6, 1.25 + k * 0.00093, -90.0, 0.0, w, h, 60.0)
        fx, fy, cx, cy, _, _ = cam.intrinsics
        ours += sum(_black_runs(world, cam, 4, cx, cy))
        ideal += sum(_black_runs(world, cam, 4, w / 2 - 0.5, h / 2 - 0.5))  # an ideal GL rasteriser
    assert ours == 2 * shots
    assert ideal < 1.5 * shots  # the half-pixel offset is real: the textbook principal point misses


def test_site_corners_project_onto_detected_corners(world: World) -> None:
    """AprilTag 3 corners of every tag in view, over several views and both sizes, vs the projection."""
    residuals, naive = [], []
    for view in (SOUTH_OBLIQUE, NORTH_WALL, WEST_WALL):
        for w, h in ((640, 480), (1280, 720)):
            cam = CameraSpec.from_degrees(*view, w, h, 60.0)
            found = _detect_apriltag(_gray(world.render(cam)))
            assert (
                len(_tags_in_view(world, cam, whole_quad=True) - set(found)) <= 1
            )  # AprilTag 3 (decimating) may miss a small one
            for tag, corners in found.items():
                predicted = cam.project(world.landmark_corners(tag))
                residuals.append(corners - predicted)
                naive.append(corners - (predicted + [-0.5, 0.5]))  # textbook (w/2 − ½, h/2 − ½)
    residuals = np.concatenate(residuals)
    assert len(residuals) >= 4 * 30
    assert np.abs(residuals).max() < 1.0  # every corner within a pixel
    assert np.linalg.norm(residuals.mean(axis=0)) < 0.2  # no half-pixel bias left (decimated AprilTag 3: ~0.1)
    assert np.linalg.norm(np.concatenate(naive).mean(axis=0)) > 0.5


@pytest.mark.parametrize(
    "view, size, max_mm, max_deg",
    [
        (SOUTH_OBLIQUE, (1280, 720), 10.0, 0.3),
        (NORTH_WALL, (1280, 720), 10.0, 0.3),
        (SOUTH_OBLIQUE, (640, 480), 25.0, 0.7),
        (WEST_WALL, (640, 480), 25.0, 0.7),
    ],
)
def test_opencv_finds_the_tags_and_the_pose_agrees_with_the_truth(
    world: World,
    site: Site,
    aruco: cv2.aruco.ArucoDetector,
    view: tuple,
    size: tuple[int, int],
    max_mm: float,
    max_deg: float,
) -> None:
    cam = CameraSpec.from_degrees(*view, *size, 60.0)
    found = _detect_opencv(aruco, _gray(world.render(cam)))
    must = _tags_in_view(world, cam, whole_quad=True)
    assert len(must) >= 4
    assert must <= set(found) <= _tags_in_view(world, cam, whole_quad=False, margin=0.0)
    residual = np.concatenate(
        [np.linalg.norm(found[t] - cam.project(world.landmark_corners(t)), axis=1) for t in found]
    )
    assert np.median(residual) < 0.7 and residual.max() < 2.5  # OpenCV's corners: noisier than AprilTag 3's
    position_error, rotation_error = _pose_error(site, cam, found, cam.K)
    assert position_error * 1000 < max_mm, f"position off by {position_error * 1000:.1f} mm"
    assert rotation_error < max_deg, f"rotation off by {rotation_error:.3f}°"


# ---------------------------------------------------------------------- messages


def test_frame_and_truth_messages(world: World) -> None:
    cam = CameraSpec.from_degrees(*SOUTH_OBLIQUE, 640, 480, 60.0)
    image = world.render(cam)
    frame = decode(encode(frame_message("tablet", image, cam)), CameraFrame)
    assert (frame.width, frame.height) == (640, 480)
    assert frame.intrinsics == pytest.approx(cam.intrinsics[:4]) and frame.distortion == [0.0] * 5
    decoded = cv2.cvtColor(cv2.imdecode(np.frombuffer(frame.jpeg, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    assert np.abs(decoded.astype(int) - image).mean() < 2.0  # colours survive (RGB, not BGR)
    truth = decode(encode(truth_message("tablet", cam, 17)), CameraTruth)
    assert truth.frame_seq == 17 and truth.position == pytest.approx(list(cam.position))
    np.testing.assert_allclose(matrix_from_quat(truth.quaternion), cam.R_world_camera, atol=1e-9)
    with pytest.raises(ValueError, match="640x480"):
        frame_message("tablet", image[:100], cam)


def test_frames_carry_gravity_as_an_imu_measures_it(world: World) -> None:
    """Gravity in the camera frame (pointing down): the truth without noise, about 1 deg off with the
    default noise, none when asked for none; the command line option is checked."""
    import argparse

    from services.sim.camfeed import add_camera_arguments, camera_options_from

    cam = CameraSpec.from_degrees(*SOUTH_OBLIQUE, 64, 48, 60.0)
    image = np.zeros((48, 64, 3), np.uint8)
    exact = decode(encode(frame_message("tablet", image, cam, gravity_noise_deg=0.0)), CameraFrame).gravity
    np.testing.assert_allclose(exact, cam.R_world_camera.T @ [0.0, 0.0, -9.80665], atol=1e-9)
    assert exact[1] > 9.0  # a camera pitched a little: gravity mostly along the image's "down"
    rng = np.random.default_rng(0)
    angles = [
        math.degrees(
            math.acos(np.clip(np.dot(frame_message("t", image, cam, rng=rng).gravity, exact) / 9.80665**2, -1, 1))
        )
        for _ in range(200)
    ]
    assert 0.8 < float(np.median(angles)) < 2.0  # two tilt axes at N(0, 1 deg) each: median ~1.2 deg
    assert frame_message("t", image, cam, gravity_noise_deg=None).gravity == []
    parser = argparse.ArgumentParser()
    add_camera_arguments(parser)
    assert camera_options_from(parser.parse_args(["--camera", "tablet"])).gravity_noise == 1.0
    assert camera_options_from(parser.parse_args(["--camera", "tablet", "--camera-no-gravity"])).gravity_noise is None
    with pytest.raises(ValueError, match="--camera-gravity-noise"):
        camera_options_from(parser.parse_args(["--camera", "tablet", "--camera-gravity-noise", "-1"]))


# ---------------------------------------------------------------------- the command


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(arroch(*args), cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_snapshot_command_writes_a_frame_the_ar_client_localises(
    tmp_path: Path, site: Site, aruco: cv2.aruco.ArucoDetector
) -> None:
    out, truth_file = tmp_path / "snap.png", tmp_path / "truth.json"
    x, y, z, yaw, pitch = SOUTH_OBLIQUE
    done = _run(
        "sim",
        "snapshot",
        "--camera",
        f"{x},{y},{z},{yaw},{pitch}",
        "--size",
        "1280x720",
        "--fov",
        "60",
        "--out",
        str(out),
        "--truth",
        str(truth_file),
    )
    assert done.returncode == 0, done.stderr
    truth = json.loads(truth_file.read_text())
    cam = CameraSpec.from_degrees(x, y, z, yaw, pitch, 1280, 720, 60.0)
    assert truth.keys() == {"position", "quaternion", "intrinsics"}
    for key, value in truth_json(cam).items():
        assert truth[key] == pytest.approx(value, abs=1e-12), key
    image = cv2.imread(str(out), cv2.IMREAD_COLOR)
    assert image.shape == (720, 1280, 3)
    fx, fy, cx, cy, _, _ = truth["intrinsics"]
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]])
    found = _detect_opencv(aruco, cv2.cvtColor(image, cv2.COLOR_BGR2GRAY))
    assert len(found) >= 4
    position_error, rotation_error = _pose_error(site, cam, found, K)
    assert position_error < 0.01 and rotation_error < 0.3
    # The AR client's own localisation (its detector, edge refinement and solver) agrees too.
    located = _run(
        "ar",
        "localize",
        "--image",
        str(out),
        "--intrinsics",
        ",".join(f"{v:.6f}" for v in truth["intrinsics"]),
        "--json",
    )
    assert located.returncode == 0, located.stdout + located.stderr
    result = json.loads(located.stdout.strip().splitlines()[-1])
    assert np.linalg.norm(np.subtract(result["position"], truth["position"])) < 0.01
    assert (
        math.degrees(rotation_angle(matrix_from_quat(result["quaternion"]), matrix_from_quat(truth["quaternion"])))
        < 0.3
    )


@pytest.mark.parametrize(
    "args, message",
    [
        ([], "--camera"),
        (["--camera", "8,2,1.3,-70"], "X,Y,Z,YAW,PITCH"),
        (["--camera", "8,2,1.3,-70,95"], "pitch"),
        (["--camera", "8,2,1.3,-70,0", "--size", "640"], "WxH"),
        (["--camera", "8,2,1.3,-70,0", "--fov", "0"], "field of view"),
        (["--camera", "8,2,1.3,-70,0", "--open", "d_nowhere"], "d_nowhere"),
        (["--camera", "8,2,1.3,-70,0", "--site", "/no/such/site.toml"], "site.toml"),
    ],
)
def test_snapshot_refuses_bad_arguments(
    tmp_path: Path, capsys: pytest.CaptureFixture, args: list[str], message: str
) -> None:
    argv = ["sim", "snapshot", *args, "--out", str(tmp_path / "a.png"), "--truth", str(tmp_path / "a.json")]
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own refusals
        code = exc.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "a.png").exists()
