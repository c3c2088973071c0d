"""The tag images are the official tag36h11 images, and both detectors' corners get the right names."""

from __future__ import annotations

import ctypes
from pathlib import Path

import cv2
import numpy as np
import pupil_apriltags
import pytest
from pupil_apriltags import bindings

from runtime.apriltag import (
    NUM_TAGS,
    apriltag_corners,
    named_corners,
    opencv_corners,
    quad_edge,
    tag_image,
    tag_image_corners,
)


def _official_from_apriltag_library() -> list[np.ndarray]:
    """Every tag36h11 image rendered from the AprilTag 3 C library's own code table and bit layout.

    This is how the official PNGs are made: a 1-module white border, a 1-module black frame, and
    data bit i (most significant first) white when set, at (bit_x[i], bit_y[i]) inside the frame.
    (The library's ``apriltag_to_image`` in this build draws a shifted border, so it is not used.)
    """
    lib = ctypes.CDLL(str(next((Path(pupil_apriltags.__file__).parent / "lib64").glob("libapriltag.so*"))))
    lib.tag36h11_create.restype = ctypes.POINTER(bindings._ApriltagFamily)
    lib.tag36h11_destroy.argtypes = [ctypes.POINTER(bindings._ApriltagFamily)]
    fam_ptr = lib.tag36h11_create()
    try:
        fam = fam_ptr.contents
        assert (fam.total_width, fam.width_at_border, fam.nbits, fam.reversed_border) == (10, 8, 36, False)
        offset = fam.total_width // 2 - fam.width_at_border // 2  # = 1: data coordinates start inside the white border
        images = []
        for idx in range(fam.ncodes):
            code = fam.codes[idx]
            img = np.full((10, 10), 255, np.uint8)
            img[1:9, 1:9] = 0
            for i in range(fam.nbits):
                if (code >> (fam.nbits - 1 - i)) & 1:
                    img[fam.bit_y[i] + offset, fam.bit_x[i] + offset] = 255
            images.append(img)
        return images
    finally:
        lib.tag36h11_destroy(fam_ptr)


def test_every_tag_image_equals_the_official_layout():
    official = _official_from_apriltag_library()
    assert len(official) == NUM_TAGS == 587
    for idx, ref in enumerate(official):
        assert np.array_equal(tag_image(idx, module_px=1, border_modules=1), ref), idx


def test_image_size_border_and_scaling():
    img = tag_image(7, module_px=6, border_modules=2)
    assert img.dtype == np.uint8 and img.shape == (72, 72)
    assert (img[:12] == 255).all() and (img[:, -12:] == 255).all()  # two white modules of quiet zone
    assert (img[12:18, 12:60] == 0).all()  # the black frame's top row of modules
    assert np.array_equal(tag_image(7, 6, 2)[12:60, 12:60], tag_image(7, 6, 0))
    assert np.array_equal(tag_image(7, 1, 1)[1:9, 1:9], tag_image(7, 1, 0))
    assert quad_edge(0.16, 1) == pytest.approx(0.2)
    assert quad_edge(0.16, 0) == pytest.approx(0.16)
    assert quad_edge(0.2, 2) == pytest.approx(0.3)
    with pytest.raises(ValueError):
        tag_image(NUM_TAGS)
    with pytest.raises(ValueError):
        tag_image(0, module_px=0)


def _scene(tag_id: int, quarter_turns: int) -> tuple[np.ndarray, np.ndarray]:
    """A tag rotated clockwise by quarter_turns·90° on a white page, and its true TL,TR,BR,BL pixels."""
    module_px, pad = 10, 40
    img = np.pad(tag_image(tag_id, module_px, 1), pad, constant_values=255)
    corners = tag_image_corners(module_px, 1) + pad
    n = img.shape[0]
    for _ in range(quarter_turns % 4):
        img = np.rot90(img, -1)  # clockwise on screen
        # a pixel (u, v) goes to (n-1-v, u) under a clockwise quarter turn
        corners = np.stack([n - 1 - corners[:, 1], corners[:, 0]], axis=1)
    return np.ascontiguousarray(img), corners


@pytest.mark.parametrize("quarter_turns", [0, 1, 2, 3])
@pytest.mark.parametrize("tag_id", [0, 42, 586])
def test_both_detectors_name_the_corners_alike(pupil, tag_id, quarter_turns):
    img, truth = _scene(tag_id, quarter_turns)
    # Where the upright tag's top-left corner lands on screen after the turn (screen TL, TR, BR, BL).
    screen_tl = {0: "TL", 1: "TR", 2: "BR", 3: "BL"}[quarter_turns]
    xs, ys = truth[0]
    centre = truth.mean(axis=0)
    assert (xs < centre[0]) == (screen_tl in ("TL", "BL")) and (ys < centre[1]) == (screen_tl in ("TL", "TR"))

    dets = pupil.detect(img)
    assert [d.tag_id for d in dets] == [tag_id]
    ours = apriltag_corners(dets[0].corners)
    assert np.abs(ours - truth).max() < 0.25, ours - truth
    assert np.array_equal(named_corners(dets[0].corners, "apriltag"), ours)

    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11))
    corners, ids, _ = detector.detectMarkers(img)
    assert ids is not None and ids.ravel().tolist() == [tag_id]
    theirs = opencv_corners(corners[0])
    # OpenCV's unrefined corners sit on the outermost black pixels' centres, 0.5 px inside the edge.
    assert np.abs(theirs - truth).max() < 0.75, theirs - truth
    assert np.array_equal(named_corners(corners[0], "opencv"), theirs)


@pytest.mark.parametrize("detector", ["opencv", "apriltag"])
def test_a_landmark_seen_from_the_front_has_its_tl_corner_top_left(detector):
    """The site's corner convention on rendered pixels: a level camera facing a wall tag sees the
    landmark's ``corners()[0]`` (TL) at the top-left of the detected quad, and each detector's named
    corners land on the projections of ``corners()`` (the texture, the site and the detectors agree)."""
    from runtime.frames import look_at
    from services.ar_client.detect import TagDetector
    from services.ar_client.project import Projector
    from services.ar_client.synth import render
    from tests.ar.helpers import HD, only_tags

    lone = only_tags("hall", (10,))
    lm = lone.landmarks[0]
    eye = look_at([lm.position[0] - 1.2, lm.position[1] + 0.2, lm.position[2] + 0.1], lm.position)
    frame = render(lone, eye, HD)
    dets = TagDetector(detector, decimate=1.0 if detector == "apriltag" else None).detect(frame.image)
    assert [d.tag_id for d in dets] == [10]
    tl, tr, br, bl = dets[0].corners
    assert tl[0] < tr[0] and bl[0] < br[0] and tl[1] < bl[1] and tr[1] < br[1]
    expected, _ = Projector(eye, HD).project_points(lm.corners())
    assert np.abs(dets[0].corners - expected).max() < 0.3


def test_a_process_using_the_apriltag_detector_exits_cleanly():
    """pupil-apriltags' own teardown frees the tag family before the detector and crashed this very
    script at exit (SIGSEGV, every run) before the detector was released in order at exit."""
    import subprocess
    import sys

    from tests.procs import ROOT

    script = (
        "import numpy as np\n"
        "from services.ar_client.detect import TagDetector\n"
        "from services.ar_client.synth import render\n"
        "from tests.ar.helpers import HD, site, view_of, CLUSTER_CENTRE\n"
        "img = render(site('hall'), view_of(CLUSTER_CENTRE, 0.0, 2.0, 20.0), HD).image\n"
        "det = TagDetector('apriltag')\n"
        "for _ in range(5):\n"
        "    assert det.detect(img)\n"
        "    det.detect_regions(img, [(0, np.array([[100.0, 100], [140, 100], [140, 140], [100, 140]]))])\n"
        "print('done')\n"
    )
    for _ in range(2):
        r = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=60)
        assert r.returncode == 0 and "done" in r.stdout, (r.returncode, r.stderr[-500:])
