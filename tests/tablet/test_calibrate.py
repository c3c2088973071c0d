"""``arroch ar calibrate`` on images synthesised with a known camera: a rendered chessboard (and a
ChArUco board) warped into the image through K·[r1 r2 t] at a dozen board poses, supersampled,
blurred and noisy. The recovered focal length must be within 2 % of the truth, the principal point
within 8 px; too few views, a bad pattern or a missing folder exit 2."""

from __future__ import annotations

import json
import subprocess

import cv2
import numpy as np
import pytest

from services.ar_client.project import Intrinsics
from services.ar_client.web.calibrate import Pattern, calibrate, image_files
from services.ar_client.web.intrinsics import load_intrinsics
from tests.procs import ROOT, arroch

TRUE = Intrinsics(1000.0, 1000.0, 645.0, 352.0, 1280, 720)
PX = 60  # texture pixels per square
SUPERSAMPLE = 2


def _rotation(ax: float, ay: float, az: float) -> np.ndarray:
    return (
        cv2.Rodrigues(np.array([ax, 0.0, 0.0]))[0]
        @ cv2.Rodrigues(np.array([0.0, ay, 0.0]))[0]
        @ cv2.Rodrigues(np.array([0.0, 0.0, az]))[0]
    )


def _poses(n: int = 12, seed: int = 3) -> list[tuple[np.ndarray, np.ndarray]]:
    """Board-to-camera rotations (tilted up to 35°) and board-centre positions 0.45–0.65 m away."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        tilt = np.radians(rng.uniform(15, 35))
        direction = 2 * np.pi * k / n
        R = _rotation(tilt * np.cos(direction), tilt * np.sin(direction), np.radians(rng.uniform(-15, 15)))
        centre = np.array([rng.uniform(-0.06, 0.06), rng.uniform(-0.04, 0.04), rng.uniform(0.45, 0.65)])
        out.append((R, centre))
    return out


def _view(texture: np.ndarray, metres_per_px: float, R: np.ndarray, centre: np.ndarray, seed: int) -> np.ndarray:
    """The texture (a board lying on its z = 0 plane, its middle at ``centre``) as the true camera sees it."""
    th, tw = texture.shape[:2]
    # Texture pixel (u, v) → board point (X, Y, 0), the texture's centre at the board origin.
    S = np.array(
        [
            [metres_per_px, 0, (0.5 - tw / 2) * metres_per_px],
            [0, metres_per_px, (0.5 - th / 2) * metres_per_px],
            [0, 0, 1],
        ]
    )
    s = SUPERSAMPLE
    K = np.array([[TRUE.fx * s, 0, (TRUE.cx + 0.5) * s - 0.5], [0, TRUE.fy * s, (TRUE.cy + 0.5) * s - 0.5], [0, 0, 1]])
    H = K @ np.column_stack([R[:, 0], R[:, 1], centre]) @ S
    big = cv2.warpPerspective(texture, H, (TRUE.width * s, TRUE.height * s), flags=cv2.INTER_LINEAR, borderValue=110)
    image = cv2.resize(big, (TRUE.width, TRUE.height), interpolation=cv2.INTER_AREA)
    image = cv2.GaussianBlur(image, (0, 0), 0.7)
    noise = np.random.default_rng(seed).normal(0.0, 2.0, image.shape)
    return np.clip(image + noise, 0, 255).astype(np.uint8)


def _chessboard_texture(cols: int, rows: int) -> np.ndarray:
    """(cols+1) × (rows+1) squares (``cols × rows`` inner corners) and a one-square white margin."""
    squares = np.indices((rows + 1, cols + 1)).sum(axis=0) % 2
    board = np.where(squares == 0, 0, 255).astype(np.uint8)
    board = np.kron(board, np.ones((PX, PX), np.uint8))
    return cv2.copyMakeBorder(board, PX, PX, PX, PX, cv2.BORDER_CONSTANT, value=255)


def _charuco_texture(pattern: Pattern) -> np.ndarray:
    board = pattern.charuco_board().generateImage((pattern.cols * PX, pattern.rows * PX), marginSize=0, borderBits=1)
    return cv2.copyMakeBorder(board, PX // 2, PX // 2, PX // 2, PX // 2, cv2.BORDER_CONSTANT, value=255)


def _write_views(folder, texture: np.ndarray, square: float) -> None:  # noqa: ANN001
    folder.mkdir(parents=True, exist_ok=True)
    for k, (R, centre) in enumerate(_poses()):
        cv2.imwrite(str(folder / f"view{k:02d}.png"), _view(texture, square / PX, R, centre, seed=k))


@pytest.mark.parametrize("spec", ["chessboard:9x6:0.025", "charuco:7x5:0.04:0.03"])
def test_recovers_the_true_intrinsics(spec, tmp_path):
    pattern = Pattern.parse(spec)
    texture = (
        _chessboard_texture(pattern.cols, pattern.rows) if pattern.kind == "chessboard" else _charuco_texture(pattern)
    )
    _write_views(tmp_path, texture, pattern.square)
    result = calibrate(image_files(tmp_path), pattern)
    K = result.intrinsics
    assert len(result.used) >= 10, result.skipped
    assert (K.width, K.height) == (TRUE.width, TRUE.height)
    assert abs(K.fx / TRUE.fx - 1) < 0.02 and abs(K.fy / TRUE.fy - 1) < 0.02, K
    assert abs(K.cx - TRUE.cx) < 8 and abs(K.cy - TRUE.cy) < 8, K
    assert result.rms_px < 0.5
    assert max(abs(d) for d in K.distortion) < 0.1  # the synthetic camera has none


def test_command_writes_a_file_the_tablet_reads(tmp_path):
    _write_views(tmp_path / "images", _chessboard_texture(9, 6), 0.025)
    out = tmp_path / "intrinsics.json"
    result = subprocess.run(
        arroch(
            "ar",
            "calibrate",
            "--images",
            str(tmp_path / "images"),
            "--pattern",
            "chessboard:9x6:0.025",
            "--out",
            str(out),
        ),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert "wrote" in result.stdout and "RMS" in result.stdout
    K = load_intrinsics(out)
    assert abs(K.fx / TRUE.fx - 1) < 0.02
    data = json.loads(out.read_text())
    assert data["pattern"] == "chessboard:9x6:0.025" and len(data["images"]) >= 10 and data["rms_px"] < 0.5


def test_too_few_views_and_bad_input_exit_2(tmp_path):
    images = tmp_path / "images"
    images.mkdir()
    cv2.imwrite(str(images / "blank.png"), np.full((480, 640), 128, np.uint8))
    for args, message in (
        (["--images", str(images), "--pattern", "chessboard:9x6:0.025"], "at least 3"),
        (["--images", str(tmp_path / "missing"), "--pattern", "chessboard:9x6:0.025"], "not a folder"),
        (["--images", str(images), "--pattern", "checkers:9x6"], "--pattern"),
        (["--images", str(images), "--pattern", "charuco:7x5:0.03:0.04"], "smaller than the square"),
    ):
        result = subprocess.run(
            arroch("ar", "calibrate", *args, "--out", str(tmp_path / "K.json")),
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert result.returncode == 2 and message in result.stderr, (args, result.stderr)
    assert not (tmp_path / "K.json").exists()
