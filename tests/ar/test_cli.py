"""``arroch ar localize``, ``arroch ar render`` and ``arroch tags sheet`` as real commands."""

from __future__ import annotations

import json
import re
import subprocess

import cv2
import numpy as np
import pytest

from runtime.frames import look_at, matrix_from_quat, rotation_angle
from services.ar_client.detect import TagDetector
from services.ar_client.synth import render
from tests.ar.helpers import HALL_FILE, HD, site
from tests.procs import ROOT, arroch

INTRINSICS = ",".join(f"{v:g}" for v in HD.as_list())
TRUTH = look_at([2.5, 3.5, 1.4], [0.05, 5.0, 1.2])


def _run(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run(arroch(*args), cwd=ROOT, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def frame_png(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("cli") / "frame.png"
    cv2.imwrite(str(path), render(site("hall"), TRUTH, HD).image)
    return str(path)


def test_localize_prints_the_pose_as_json(frame_png):
    r = _run("ar", "localize", "--site", str(HALL_FILE), "--image", frame_png, "--intrinsics", INTRINSICS, "--json")
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout)
    assert data["ok"] is True and len(data["tags"]) >= 4
    assert np.linalg.norm(np.array(data["position"]) - TRUTH.position) < 0.01
    assert np.degrees(rotation_angle(matrix_from_quat(data["quaternion"]), TRUTH.R_wc)) < 0.3
    assert 0.0 <= data["reprojection_rmse_px"] < 0.5


def test_localize_says_why_when_it_cannot(tmp_path):
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((HD.height, HD.width), 200, np.uint8))
    r = _run("ar", "localize", "--site", str(HALL_FILE), "--image", str(blank), "--intrinsics", INTRINSICS, "--json")
    assert r.returncode == 1
    data = json.loads(r.stdout)
    assert data == {"ok": False, "reason": "no landmark tag in view", "tags": []}
    wrong_size = _run(
        "ar", "localize", "--site", str(HALL_FILE), "--image", str(blank), "--intrinsics", "500,500,320,240,640,480"
    )
    assert wrong_size.returncode == 2 and "1280x720" in wrong_size.stderr
    missing = _run(
        "ar", "localize", "--site", str(HALL_FILE), "--image", str(tmp_path / "nope.png"), "--intrinsics", INTRINSICS
    )
    assert missing.returncode == 2 and "cannot read image" in missing.stderr


def test_render_draws_a_state_file_over_an_image(frame_png, tmp_path):
    state = {
        "time": 0.0,
        "poses": {"r0": [2.0, 5.0, 0.0]},
        "intents": {"r0": [[0, 2.0, 5.0, 0], [10, 1.0, 4.0, 0]]},
        "doors": {},
    }
    state_file = tmp_path / "state.json"
    state_file.write_text(json.dumps(state))
    out = tmp_path / "out.png"
    r = _run(
        "ar",
        "render",
        "--site",
        str(HALL_FILE),
        "--image",
        frame_png,
        "--intrinsics",
        INTRINSICS,
        "--state",
        str(state_file),
        "--out",
        str(out),
    )
    assert r.returncode == 0, r.stderr
    drawn = cv2.imread(str(out))
    plain = cv2.imread(frame_png)
    assert drawn.shape == plain.shape
    changed = np.abs(drawn.astype(int) - plain.astype(int)).max(axis=2) > 30
    assert changed.sum() > 500  # the avatar, path and status were drawn
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"poses": {"r0": [1, 2]}}))
    r = _run(
        "ar",
        "render",
        "--site",
        str(HALL_FILE),
        "--image",
        frame_png,
        "--intrinsics",
        INTRINSICS,
        "--state",
        str(bad),
        "--out",
        str(out),
    )
    assert r.returncode == 2 and "poses.r0" in r.stderr


def test_tags_sheet_pdf_has_one_true_size_page_per_landmark(tmp_path):
    pdf = tmp_path / "tags.pdf"
    r = _run("tags", "sheet", "--site", str(HALL_FILE), "--out", str(pdf))
    assert r.returncode == 0, r.stderr
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF")
    assert len(re.findall(rb"/Type\s*/Page\b", data)) == len(site("hall").landmarks)


def test_tags_sheet_png_pages_decode_upright_at_true_size(tmp_path):
    """Each PNG page holds the landmark's tag: both detectors read the right id, its TL corner is the
    image's top-left (upright), and its black square measures the landmark's size at the page's dpi."""
    dpi = 150
    r = _run("tags", "sheet", "--site", str(HALL_FILE), "--out", str(tmp_path / "sheet.png"), "--dpi", str(dpi))
    assert r.returncode == 0, r.stderr
    opencv = TagDetector("opencv")
    for lm in site("hall").landmarks[:3]:
        page = cv2.imread(str(tmp_path / f"sheet_{lm.tag}.png"), cv2.IMREAD_GRAYSCALE)
        for dets in (opencv.detect(page), TagDetector("apriltag", decimate=2.0).detect(page)):
            assert [d.tag_id for d in dets] == [lm.tag]
            c = dets[0].corners
            assert c[0][0] < c[1][0] and c[0][1] < c[3][1]  # TL left of TR and above BL: upright
            edge_px = np.mean(np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1))
            assert edge_px / dpi * 0.0254 == pytest.approx(lm.size, rel=0.01)


def test_localize_takes_gravity_and_picks_a_single_tags_right_solution(tmp_path):
    from runtime.frames import gravity_in_camera
    from tests.ar.helpers import VGA, only_tags
    from tests.ar.test_gravity import single_tag_view

    truth = single_tag_view(-30.0)
    path = tmp_path / "one-tag.png"
    cv2.imwrite(str(path), render(only_tags("hall", (10,)), truth, VGA, seed=430).image)
    common = (
        "ar",
        "localize",
        "--site",
        str(HALL_FILE),
        "--image",
        str(path),
        "--intrinsics",
        ",".join(f"{v:g}" for v in VGA.as_list()),
        "--json",
    )
    blind = json.loads(_run(*common).stdout)
    assert blind["ok"] and blind["ambiguous"] and "gravity_error_deg" not in blind
    g = ",".join(f"{v:.4f}" for v in gravity_in_camera(truth.R_wc))
    seen = json.loads(_run(*common, "--gravity", g).stdout)
    assert seen["ok"] and seen["gravity_error_deg"] < 2.0
    assert (
        np.linalg.norm(np.array(seen["position"]) - truth.position)
        < 0.1
        < np.linalg.norm(np.array(blind["position"]) - truth.position)
    )
    bad = _run(*common, "--gravity", "1,2")
    assert bad.returncode == 2 and "gravity" in bad.stderr


def test_apriltag_detector_without_its_library_is_a_usage_error_naming_the_extra(monkeypatch, capsys):
    import sys

    from services.cli import main

    monkeypatch.setitem(sys.modules, "pupil_apriltags", None)  # `import pupil_apriltags` now fails
    with pytest.raises(SystemExit) as exited:
        main(["ar", "localize", "--image", "x.png", "--detector", "apriltag"])
    assert exited.value.code == 2
    assert "pip install 'arroch[apriltag]'" in capsys.readouterr().err
    with pytest.raises(ValueError, match=r"arroch\[apriltag\]"):
        TagDetector("apriltag")


@pytest.mark.parametrize("given", ["-0.1,9.8,0.2", "-.1,9.8,0.2", "0.1,9.8,-0.2"])
def test_localize_takes_a_gravity_that_starts_with_a_minus_as_its_value(given):
    """``--gravity -0.1,9.8,0.2`` (space, not '='): a value, though argparse reads most '-' words as options."""
    from services.cli import build_parser

    argv = ["ar", "localize", "--image", "x.png", "--intrinsics", "500,500,320,240,640,480", "--gravity", given]
    args = build_parser().parse_args(argv)
    assert args.gravity == given


def test_localize_with_a_negative_gravity_runs_end_to_end(frame_png):
    intrinsics = ",".join(f"{v:g}" for v in HD.as_list())
    argv = ("--site", str(HALL_FILE), "--image", frame_png, "--intrinsics", intrinsics, "--json")
    result = _run("ar", "localize", *argv, "--gravity", "-0.1,9.8,0.2")
    assert result.returncode in (0, 1), result.stderr  # a pose or none: never a usage error
    assert "gravity_error_deg" in json.loads(result.stdout) or not json.loads(result.stdout)["ok"]
