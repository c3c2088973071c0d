"""Small tags (10-18 px) read from ArUco's rejected quads: found at least as often as by AprilTag 3
at full resolution, with the right corners and no invented tags."""

from __future__ import annotations

import cv2
import numpy as np

from runtime.frames import look_at
from services.ar_client.detect import TagDetector
from services.ar_client.smalltags import decode_quads
from services.ar_client.synth import render
from tests.ar.helpers import CLUSTER_CENTRE, VGA, site


def far_views() -> list:
    """Cameras 6-9 m from the hall's west-wall cluster: its 0.16 m tags are 10-16 px at 640x480."""
    out = []
    for k, (d, side) in enumerate([(6.0, -1.5), (7.0, 0.0), (8.0, 1.0), (9.0, -0.5), (7.5, 2.0), (6.5, 0.8)]):
        out.append((k, look_at([d, CLUSTER_CENTRE[1] + side, 1.2 + 0.1 * k], CLUSTER_CENTRE)))
    return out


def test_small_tags_found_at_least_as_often_as_apriltag3(pupil):
    hall = site("hall")
    known = [lm.tag for lm in hall.landmarks]
    ours, reference = TagDetector("opencv", known_ids=known), TagDetector("apriltag", known_ids=known, decimate=1.0)
    plain = TagDetector("opencv", known_ids=known, small_tags=False)
    counts = {"ours": 0, "reference": 0, "plain": 0, "in_view": 0}
    sides = []
    for seed, pose in far_views():
        frame = render(hall, pose, VGA, seed=seed, noise_sigma=2.5, blur_sigma=0.8)
        counts["in_view"] += len(frame.in_view)
        sides += [float(np.sqrt(cv2.contourArea(frame.corners[t].astype(np.float32)))) for t in frame.in_view]
        for name, det in (("ours", ours), ("reference", reference), ("plain", plain)):
            found = det.detect(frame.image)
            assert {d.tag_id for d in found} <= set(frame.in_view), name  # nothing invented
            counts[name] += len(found)
            if name == "ours":
                for d in found:  # corners of the tag found, not of a neighbour or a rotation of it
                    assert np.abs(d.corners - frame.corners[d.tag_id]).max() < 1.0
    assert 9.0 < np.median(sides) < 16.0, sides
    assert counts["ours"] >= counts["reference"], counts
    assert counts["ours"] >= counts["plain"] + 0.3 * counts["in_view"], counts  # the decoding is what finds them


def test_the_corner_order_is_found_whatever_corner_the_quad_starts_at():
    """A quad handed over starting at any of its corners, either winding: the tag's own TL, TR, BR, BL come back."""
    from runtime.apriltag import opencv_corners

    hall = site("hall")
    pose = look_at([7.0, CLUSTER_CENTRE[1] + 0.5, 1.3], CLUSTER_CENTRE)
    frame = render(hall, pose, VGA, seed=3, noise_sigma=2.0, blur_sigma=0.7)
    tag = frame.in_view[0]
    truth = frame.corners[tag]
    for k in range(4):
        for quad in (np.roll(truth, k, axis=0), np.roll(truth, k, axis=0)[::-1]):
            noisy = quad + np.random.default_rng(k).normal(0.0, 0.5, quad.shape)
            found = decode_quads(frame.image, [noisy], frozenset(lm.tag for lm in hall.landmarks))
            assert [f[0] for f in found] == [tag]
            assert np.abs(opencv_corners(found[0][1]) - truth).max() < 0.7, k


def test_noise_and_texture_decode_to_nothing():
    rng = np.random.default_rng(0)
    det = TagDetector("opencv")  # every one of the 587 codes allowed: the hardest case for false positives
    for k in range(6):
        noise = rng.integers(0, 256, (480, 640)).astype(np.uint8)
        blocks = cv2.resize(
            rng.integers(0, 2, (60, 80)).astype(np.uint8) * 255, (640, 480), interpolation=cv2.INTER_NEAREST
        )
        image = cv2.GaussianBlur(noise if k % 2 else blocks, (0, 0), 0.7 + 0.2 * k)
        assert det.detect(image) == []


def test_decode_quads_skips_big_and_degenerate_quads():
    gray = np.full((100, 100), 128, np.uint8)
    big = np.array([[0, 0], [90, 0], [90, 90], [0, 90]], float)
    flat = np.array([[10, 10], [30, 10], [30, 10.5], [10, 10.5]], float)
    assert decode_quads(gray, [big, flat]) == []
