"""Small-tag reading is skipped only on frames that already hold enough well-seen tags.

Counted, not timed: the detector's ``small_tag_passes`` (reading ran) and ``small_tag_skips`` (a frame
with rejected quads where it did not)."""

from __future__ import annotations

import numpy as np
import pytest

from services.ar_client.detect import SKIP_SMALL_AT_TAGS, WELL_SEEN_PX, TagDetection, TagDetector, tag_side_px
from services.ar_client.pipeline import Pipeline
from services.ar_client.refine import _module_px, _principal_directions
from services.ar_client.smalltags import quad_signed_area
from services.ar_client.synth import render
from tests.ar.helpers import CLUSTER_CENTRE, HD, VGA, site, view_of
from tests.ar.test_smalltags import far_views


def hall_detector(**options) -> TagDetector:  # noqa: ANN003
    return TagDetector("opencv", known_ids=[lm.tag for lm in site("hall").landmarks], **options)


def square(side: float, x0: float = 0.0) -> np.ndarray:
    return np.array([[x0, 0.0], [x0 + side, 0.0], [x0 + side, side], [x0, side]])


@pytest.mark.parametrize(
    ("sides", "skip"),
    [
        ([80.0] * SKIP_SMALL_AT_TAGS, True),
        ([WELL_SEEN_PX] * SKIP_SMALL_AT_TAGS, True),
        ([80.0] * (SKIP_SMALL_AT_TAGS - 1) + [20.0] * 5, False),  # many tags, too few of them well seen
        ([WELL_SEEN_PX - 1.0] * 8, False),  # a far view: every tag read, every one small
        ([80.0] * (SKIP_SMALL_AT_TAGS - 1), False),
    ],
)
def test_the_rule_counts_well_seen_tags_only(sides: list[float], skip: bool) -> None:
    found = [TagDetection(i, square(side, 200.0 * i), "opencv") for i, side in enumerate(sides)]
    assert hall_detector()._enough_well_seen(found) is skip
    assert hall_detector(skip_small_at=None)._enough_well_seen(found) is False


def test_a_far_view_whose_only_tags_are_small_is_read() -> None:
    """6-9 m from the cluster at 640x480: tags of 9-14 px, ArUco reads few of them itself; the small-tag
    reading runs on every such frame and finds the tags the skip would have lost."""
    hall = site("hall")
    detector = hall_detector()
    read_by_decoding = 0
    for seed, pose in far_views():
        frame = render(hall, pose, VGA, seed=seed, noise_sigma=2.5, blur_sigma=0.8)
        passes = detector.small_tag_passes
        found = detector.detect(frame.image)
        assert detector.small_tag_passes == passes + 1, seed
        read_by_decoding += sum(d.decision_margin > 0.0 for d in found)  # the decoding's correlation score
    assert detector.small_tag_skips == 0
    assert read_by_decoding >= 12


def test_a_far_view_is_read_in_the_pipeline_too() -> None:
    hall = site("hall")
    pipeline = Pipeline(hall, detector=hall_detector())
    seed, pose = far_views()[1]
    frame = render(hall, pose, VGA, seed=seed, noise_sigma=2.5, blur_sigma=0.8)
    pipeline.process(frame.image, VGA, 0.0)
    assert pipeline.detector.small_tag_skips == 0
    assert pipeline.detector.small_tag_passes >= 1
    assert pipeline.last_localization is not None and pipeline.last_localization.ok


def test_a_close_view_skips_the_reading_and_loses_no_tag() -> None:
    """1.6 m from the cluster at 1280x720: four tags of 66-90 px, all read by ArUco itself."""
    hall = site("hall")
    frame = render(hall, view_of(CLUSTER_CENTRE, 0.0, 1.6, 10.0), HD, seed=1)
    assert len(frame.in_view) >= SKIP_SMALL_AT_TAGS
    skipping, reading = hall_detector(), hall_detector(skip_small_at=None)
    found = skipping.detect(frame.image)
    assert (skipping.small_tag_passes, skipping.small_tag_skips) == (0, 1)
    assert [d.tag_id for d in found] == sorted(frame.in_view)
    assert [d.tag_id for d in reading.detect(frame.image)] == [d.tag_id for d in found]
    assert (reading.small_tag_passes, reading.small_tag_skips) == (1, 0)

    pipeline = Pipeline(hall, detector=hall_detector())
    pipeline.process(frame.image, HD, 0.0)
    assert (pipeline.detector.small_tag_passes, pipeline.detector.small_tag_skips) == (0, 1)
    assert sorted(pipeline.last_localization.tags) == sorted(frame.in_view)


def test_skip_count_must_be_positive() -> None:
    with pytest.raises(ValueError, match="skip_small_at"):
        hall_detector(skip_small_at=0)


def test_principal_direction_matches_the_leading_eigenvector() -> None:
    """The edge fit's closed form against numpy's eigh, on point sets of every orientation and spread."""
    rng = np.random.default_rng(0)
    spread = rng.normal(size=(64, 24, 2)) * rng.uniform(0.05, 3.0, (64, 1, 2))
    angle = rng.uniform(0.0, np.pi, 64)
    turn = np.stack([np.cos(angle), -np.sin(angle), np.sin(angle), np.cos(angle)], axis=1).reshape(64, 2, 2)
    centred = np.einsum("nij,nkj->nki", turn, spread)
    centred -= centred.mean(axis=1, keepdims=True)
    direction = _principal_directions(centred)
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred))
    assert np.allclose(np.abs(np.einsum("ni,ni->n", direction, vectors[..., :, 1])), 1.0, atol=1e-9)


def test_after_a_close_view_the_quick_first_pass_settles_the_next_one() -> None:
    """The first frame gets the full pass; a close view after a close view is settled by the first pass
    (big tags only), which reads the same tags at the same corners as the full pass."""
    hall = site("hall")
    frame = render(hall, view_of(CLUSTER_CENTRE, 0.0, 1.6, 10.0), HD, seed=1)
    quick, full = hall_detector(), hall_detector(first_pass=False)
    first = quick.detect(frame.image)
    assert (quick.frames_searched, quick.first_pass_frames, quick.close_view) == (1, 0, True)
    second = quick.detect(frame.image)
    assert (quick.frames_searched, quick.first_pass_frames) == (2, 1)
    reference = full.detect(frame.image)
    assert full.first_pass_frames == 0 and full.close_view is True  # it knows, but never tries
    assert [d.tag_id for d in second] == [d.tag_id for d in first] == [d.tag_id for d in reference]
    for a, b in zip(second, reference, strict=True):
        assert np.abs(a.corners - b.corners).max() < 0.25, a.tag_id


def test_a_far_view_never_tries_the_first_pass_and_the_next_close_one_gets_the_full_pass(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    hall = site("hall")
    detector = hall_detector()
    tried: list[int] = []
    real = detector._first_pass

    def counting(gray, lens):  # noqa: ANN001, ANN202
        tried.append(gray.shape[1])
        return real(gray, lens)

    monkeypatch.setattr(detector, "_first_pass", counting)
    close = render(hall, view_of(CLUSTER_CENTRE, 0.0, 1.6, 10.0), HD, seed=1)
    detector.detect(close.image)
    seed, pose = far_views()[0]
    far = render(hall, pose, VGA, seed=seed, noise_sigma=2.5, blur_sigma=0.8)
    detector.detect(far.image)  # tried after the close view: it does not settle a far one
    assert tried == [VGA.width] and detector.first_pass_frames == 0 and detector.close_view is False
    detector.detect(far.image)
    detector.detect(close.image)
    assert tried == [VGA.width]  # neither after the far view
    assert detector.close_view is True and detector.first_pass_frames == 0
    detector.detect(close.image)
    assert tried == [VGA.width, HD.width] and detector.first_pass_frames == 1


def test_no_first_pass_without_the_skip() -> None:
    """Reading small tags on every frame means the full pass on every frame."""
    hall = site("hall")
    frame = render(hall, view_of(CLUSTER_CENTRE, 0.0, 1.6, 10.0), HD, seed=1)
    detector = hall_detector(skip_small_at=None)
    for _ in range(2):
        detector.detect(frame.image)
    assert detector.first_pass_frames == 0 and detector.small_tag_passes == 2


def test_tag_size_in_plain_floats_matches_numpy() -> None:
    rng = np.random.default_rng(3)
    for quad in rng.uniform(-50.0, 900.0, (200, 4, 2)):
        x, y = quad[:, 0], quad[:, 1]
        area = 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
        assert quad_signed_area(quad) == pytest.approx(area, rel=1e-12, abs=1e-9)
        assert tag_side_px(quad) == pytest.approx(np.sqrt(abs(area)), rel=1e-12, abs=1e-9)
        sides = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1)
        assert _module_px(quad) == pytest.approx(sides.mean() / 8.0, rel=1e-12)
