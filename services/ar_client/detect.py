"""AprilTag 36h11 detection: image → tag ids with corners named TL, TR, BR, BL (OpenCV pixel convention).

Two back ends, both returning :class:`TagDetection` with corners already reordered by
:mod:`runtime.apriltag` (the rest of the client never sees a detector's own corner order):

* ``opencv`` (default) — OpenCV's ArUco detector with ``DICT_APRILTAG_36h11``, its corners then
  refined by fitting the tag's four edges (:mod:`refine`).
* ``apriltag`` — the AprilTag 3 C library through ``pupil-apriltags`` (the ``arroch[apriltag]``
  extra: asking for it without the library is an error naming the extra). One detector lives per
  process (:func:`apriltag_detector`), released at exit in the right order (the package's own
  teardown frees in the wrong order and can crash the process).

Why the default (``benchmarks/ar.py``, section ``detectors``, same frames for all): OpenCV's ArUco
finds more tags than AprilTag 3 at decimation 2 (which loses small tags, most at 640x480), and its
time is steady (3-7 ms a frame on one core) where AprilTag 3's grows with image noise (1-2 ms on
the simulator's clean frames, 7-30 ms on noisy ones). Its own corners are poor (0.4-0.8 px RMS:
unrefined they sit on the outermost black pixels; SUBPIX looks at a small window per corner), but
the edge fit brings them to AprilTag 3's accuracy (~0.1 px on anti-aliased frames, ~0.4 px on the
simulator's aliased ones) for under a millisecond a frame. AprilTag 3 at full resolution detects a
little more but costs several times the time.

Guided second pass (:meth:`TagDetector.detect_regions`): once a pose is known, landmarks predicted
in view but not found are searched again in a crop around their predicted position (upscaled when
small). That recovers small or blurred tags for about a millisecond per crop.

Small tags (:mod:`smalltags`): ArUco's rejected quads are read again by correlation with each code,
except on a frame where ArUco itself already read :data:`SKIP_SMALL_AT_TAGS` tags at least
:data:`WELL_SEEN_PX` across (a close, many-tag view: the reading would cost time and add nothing the
pose needs). ``small_tag_passes`` and ``small_tag_skips`` count both outcomes.

Detections whose corners come within :data:`BORDER_MARGIN_PX` of the image edge are dropped: the
AprilTag library clamps the corners of tags cut by the image edge, and a cut tag's edge fit would
run off the image too.
"""

from __future__ import annotations

import argparse
import atexit
import logging
import math
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from runtime.apriltag import apriltag_corners, opencv_corners

from .refine import Lens, refine_corners
from .smalltags import decode_quads, quad_signed_area

log = logging.getLogger("arroch.ar.detect")

#: A detection whose corners come closer than this to the image (or crop) edge is dropped (pixels).
BORDER_MARGIN_PX = 2.0
#: Frames up to this many pixels are searched at full resolution by the AprilTag back end.
FULL_RES_MAX_PIXELS = 500_000
#: Edge-fit passes over ArUco's corners (a second pass re-centres the profiles on small tags' edges).
REFINE_PASSES = 2
#: The back ends ``--detector`` accepts.
DETECTORS = ("opencv", "apriltag")
#: Crops whose predicted tag is smaller than this (pixels across) are upscaled ×2 before the search.
UPSCALE_BELOW_PX = 40.0
#: Small-tag reading is skipped on a frame where ArUco itself already read this many of the site's tags
#: at least :data:`WELL_SEEN_PX` across (square root of the black square's area): such a frame is a
#: close, many-tag view whose pose those tags already fix, and a small tag the skip leaves unread is
#: still searched for by the pipeline's guided second pass (up to 75 deg off its normal). On the close
#: views the skip leaves ~0.4 % of the tags unread, all 70-78 deg oblique, with no loss of pose accuracy;
#: the hard set's frames (1-3 tags in view) never reach the count (``benchmarks/ar.py --close``, ``--hard``).
SKIP_SMALL_AT_TAGS = 4
WELL_SEEN_PX = 32.0
#: The quick first pass over a whole frame (OpenCV back end) looks only for tags at least this many
#: pixels across, with one adaptive-threshold window (:data:`FIRST_PASS_WINDOW_PX`): the data modules
#: of big tags, most of the full pass's candidates on close views, are then never traced or decoded.
#: It is tried only when the detector's previous frame held :data:`SKIP_SMALL_AT_TAGS` well-seen tags
#: (a camera's view changes little from one frame to the next): on far views it would cost ~3.5 ms
#: for nothing. When it reads that many well-seen tags, its reads are the frame's (a mid-size tag it
#: leaves unread is still searched for by the pipeline's guided second pass); otherwise the full pass
#: runs. Close views at 1280x720: ArUco's part 8.8 -> 5.4 ms a frame (``benchmarks/ar.py --close``).
FIRST_PASS_MIN_SIDE_PX = 24.0
FIRST_PASS_WINDOW_PX = 23

_pupil_lock = threading.Lock()
_pupil_detector = None


@dataclass(frozen=True)
class TagDetection:
    """One detected tag: its id and its corners TL, TR, BR, BL in pixels (OpenCV convention)."""

    tag_id: int
    corners: np.ndarray  # (4, 2) float64
    detector: str  # "apriltag" or "opencv"
    decision_margin: float = 0.0  # AprilTag's decoding confidence (0 when the detector gives none)
    hamming: int = 0  # bits corrected while decoding


def apriltag_detector():  # -> pupil_apriltags.Detector
    """The process-wide pupil-apriltags detector, created on first use and kept for the process's life."""
    global _pupil_detector
    with _pupil_lock:
        if _pupil_detector is None:
            import pupil_apriltags  # lazily: only processes that detect tags load the C library

            _pupil_detector = pupil_apriltags.Detector(families="tag36h11", nthreads=1, quad_decimate=2.0)
            atexit.register(_release_apriltag_detector)
        return _pupil_detector


def _release_apriltag_detector() -> None:
    """Free the detector in the right order before the interpreter tears down.

    pupil-apriltags' ``Detector.__del__`` destroys the tag family *before* the detector, whose
    destruction then reads the family's freed decode table: a use-after-free that crashes the
    process at exit (segmentation fault) depending on the heap's state. Here the detector goes
    first, then the family, and ``__del__`` finds nothing left to do.
    """
    det = _pupil_detector
    if det is None or det.tag_detector_ptr is None:
        return
    ptr, det.tag_detector_ptr = det.tag_detector_ptr, None
    det.libc.apriltag_detector_destroy.restype = None
    det.libc.apriltag_detector_destroy(ptr)
    det.libc.tag36h11_destroy.restype = None
    for family in det.tag_families.values():
        det.libc.tag36h11_destroy(family)
    det.tag_families = {}


def apriltag_available() -> bool:
    try:
        import pupil_apriltags  # noqa: F401
    except ImportError:
        return False
    return True


APRILTAG_MISSING = (
    "--detector apriltag needs the AprilTag 3 library (pupil-apriltags), which is not installed: "
    "pip install 'arroch[apriltag]'"
)


def detector_method(name: str) -> str:
    """``--detector`` value check: a known back end whose library is installed (argparse ``type``)."""
    if name not in DETECTORS:
        raise argparse.ArgumentTypeError(f"unknown detector {name!r} (expected one of: {', '.join(DETECTORS)})")
    if name == "apriltag" and not apriltag_available():
        raise argparse.ArgumentTypeError(APRILTAG_MISSING)
    return name


def touches_border(corners: np.ndarray, width: int, height: int, margin: float = BORDER_MARGIN_PX) -> bool:
    """True when any corner lies within ``margin`` pixels of the image edge (or outside it)."""
    u, v = corners[:, 0], corners[:, 1]
    return bool(
        (u < margin).any() or (v < margin).any() or (u > width - 1 - margin).any() or (v > height - 1 - margin).any()
    )


def tag_side_px(corners: np.ndarray) -> float:
    """A tag's size in the image: the square root of the area of its (4, 2) corners' quad, in pixels."""
    return math.sqrt(abs(quad_signed_area(corners)))


def to_gray(image: np.ndarray) -> np.ndarray:
    """A contiguous uint8 single-channel view of a BGR/BGRA/gray image."""
    if image.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        image = cv2.cvtColor(image, code)
    return np.ascontiguousarray(image, dtype=np.uint8)


class TagDetector:
    """Finds tag36h11 tags in grayscale frames with one of the back ends described above.

    ``known_ids`` (the site's landmark ids) filters out decodings of tags the site does not have —
    with 587 codes and 2-bit error correction, a stray decode of a foreign pattern is rare but would
    otherwise enter the pose as an outlier.
    """

    def __init__(
        self,
        method: str = "opencv",
        *,
        known_ids: Iterable[int] | None = None,
        decimate: float | None = None,
        max_hamming: int = 1,
        opencv_refine: str = "edges",
        small_tags: bool = True,
        skip_small_at: int | None = SKIP_SMALL_AT_TAGS,
        first_pass: bool = True,
    ) -> None:
        if method not in DETECTORS:
            raise ValueError(f"unknown detector {method!r} (expected 'apriltag' or 'opencv')")
        if method == "apriltag" and not apriltag_available():
            raise ValueError(APRILTAG_MISSING)
        self.method = method
        self.known_ids = None if known_ids is None else frozenset(int(i) for i in known_ids)
        self.decimate = decimate
        self.max_hamming = max_hamming
        self.refine_passes = REFINE_PASSES
        self.small_tags = small_tags  # OpenCV back end: read small tags from ArUco's rejected quads
        # ... except on frames with this many well-seen tags already (None: on every frame).
        if skip_small_at is not None and skip_small_at < 1:
            raise ValueError(f"skip_small_at must be a positive tag count or None, got {skip_small_at!r}")
        self.skip_small_at = skip_small_at
        # How often the small-tag reading ran and was skipped (all images searched, crops included).
        self.small_tag_passes = 0
        self.small_tag_skips = 0
        # Whole frames searched, and how many of them the quick first pass settled.
        self.frames_searched = 0
        self.first_pass_frames = 0
        # Whether the last whole frame held enough well-seen tags: the next one then tries the first pass.
        self.close_view = False
        self._lock = threading.Lock()  # the pupil detector's decimation is per-call state
        self._first_params: cv2.aruco.DetectorParameters | None = None  # the quick first pass's (OpenCV only)
        if method == "apriltag":
            self._pupil = apriltag_detector()
        else:
            if opencv_refine not in ("edges", "none", "subpix", "apriltag"):
                raise ValueError(f"unknown corner refinement {opencv_refine!r}")
            self.refine = opencv_refine
            params = cv2.aruco.DetectorParameters()
            # Adaptive-threshold windows 3 and 23 px instead of 3, 13 and 23: a third less time for
            # the same detection rate on our frames (benchmarks/ar.py).
            params.adaptiveThreshWinSizeStep = 20
            # Candidates may reach the image edge: a tag near it has only a sliver of quiet zone
            # inside, and ArUco's default 3-px margin then loses it (AprilTag 3 does not). Tags
            # actually cut by the edge are dropped by touches_border on the black square's corners.
            params.minDistanceToBorder = 0
            params.cornerRefinementMethod = {
                "edges": cv2.aruco.CORNER_REFINE_NONE,  # ours runs afterwards (refine.py)
                "none": cv2.aruco.CORNER_REFINE_NONE,
                "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
                "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG,
            }[opencv_refine]
            dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
            self._aruco = cv2.aruco.ArucoDetector(dictionary, params)
            if first_pass and skip_small_at is not None:  # it can only settle a frame the skip applies to
                self._first_params = cv2.aruco.DetectorParameters()
                for name in ("minDistanceToBorder", "cornerRefinementMethod"):
                    setattr(self._first_params, name, getattr(params, name))
                self._first_params.adaptiveThreshWinSizeMin = FIRST_PASS_WINDOW_PX
                self._first_params.adaptiveThreshWinSizeMax = FIRST_PASS_WINDOW_PX
                self._first_aruco = cv2.aruco.ArucoDetector(dictionary, self._first_params)

    def _decimation_for(self, gray: np.ndarray) -> float:
        if self.decimate is not None:
            return self.decimate
        return 1.0 if gray.shape[0] * gray.shape[1] <= FULL_RES_MAX_PIXELS else 2.0

    def _keep(self, tag_id: int) -> bool:
        return self.known_ids is None or tag_id in self.known_ids

    def _run(self, gray: np.ndarray, decimate: float, lens: Lens | None = None) -> list[TagDetection]:
        """Raw detections of one image (no border filtering); ``lens``: the frame's distortion, for the edge fit."""
        out: list[TagDetection] = []
        if self.method == "apriltag":
            with self._lock:
                self._pupil.tag_detector_ptr.contents.quad_decimate = float(decimate)
                dets = self._pupil.detect(gray)
            for d in dets:
                if d.hamming <= self.max_hamming and self._keep(d.tag_id):
                    out.append(
                        TagDetection(
                            int(d.tag_id),
                            apriltag_corners(d.corners),
                            "apriltag",
                            float(d.decision_margin),
                            int(d.hamming),
                        )
                    )
        else:
            found, rejected = self._aruco_reads(self._aruco, gray, lens)
            out += found
            if self.small_tags and rejected:
                if self._enough_well_seen(out):
                    self.small_tag_skips += 1
                else:
                    self.small_tag_passes += 1
                    out += self._small(gray, rejected, out, lens)
        return out

    def _aruco_reads(
        self, aruco: cv2.aruco.ArucoDetector, gray: np.ndarray, lens: Lens | None
    ) -> tuple[list[TagDetection], Sequence[np.ndarray]]:
        """The site's tags ``aruco`` reads in ``gray``, corners refined, and the quads it rejected."""
        corners, ids, rejected = aruco.detectMarkers(gray)
        if ids is None:
            return [], rejected
        kept = [(int(i), opencv_corners(c)) for c, i in zip(corners, ids.ravel(), strict=True) if self._keep(int(i))]
        quads = [q for _, q in kept]
        if self.refine == "edges":
            quads = refine_corners(gray, quads, self.refine_passes, lens)
        return [TagDetection(i, q, "opencv") for (i, _), q in zip(kept, quads, strict=True)], rejected

    def _first_pass(self, gray: np.ndarray, lens: Lens | None) -> list[TagDetection] | None:
        """The quick pass's reads (:data:`FIRST_PASS_MIN_SIDE_PX`) when they hold enough well-seen tags, else None."""
        if self._first_params is None:
            return None
        # ArUco's smallest candidate is a perimeter relative to the image's longer side.
        rate = 4.0 * FIRST_PASS_MIN_SIDE_PX / max(gray.shape)
        if rate != self._first_params.minMarkerPerimeterRate:
            self._first_params.minMarkerPerimeterRate = rate
            self._first_aruco.setDetectorParameters(self._first_params)
        found, _ = self._aruco_reads(self._first_aruco, gray, lens)
        return found if self._enough_well_seen(found) else None

    def _enough_well_seen(self, found: list[TagDetection]) -> bool:
        """Whether ``found`` (ArUco's own reads) holds :attr:`skip_small_at` tags of :data:`WELL_SEEN_PX` or more."""
        if self.skip_small_at is None or len(found) < self.skip_small_at:
            return False
        well_seen = sum(tag_side_px(d.corners) >= WELL_SEEN_PX for d in found)
        return well_seen >= self.skip_small_at

    def _small(
        self, gray: np.ndarray, rejected: Sequence[np.ndarray], found: list[TagDetection], lens: Lens | None
    ) -> list[TagDetection]:
        """Small tags read from ArUco's rejected quads (:mod:`smalltags`), outside the tags already found.

        A candidate centred inside a found tag is a piece of it (on close views most rejected quads
        are islands of a big tag's data modules), never another tag: dropping those first keeps the
        decoding's cost to the candidates that can be tags."""
        quads = [r.reshape(4, 2).astype(np.float64) for r in rejected]
        if found and quads:
            centres = np.array([q.mean(axis=0) for q in quads])
            inside = _inside_any(centres, np.array([d.corners for d in found]))
            quads = [q for q, drop in zip(quads, inside, strict=True) if not drop]
        return [
            TagDetection(i, opencv_corners(q), "opencv", score)
            for i, q, score in decode_quads(gray, quads, self.known_ids, lens)
        ]

    def detect(self, image: np.ndarray, lens: Lens | None = None) -> list[TagDetection]:
        """All known tags in the frame, wholly inside it, one detection per id (the most confident).

        OpenCV back end: after a close, many-tag view, a quick first pass for big tags
        (:data:`FIRST_PASS_MIN_SIDE_PX`) may settle the next frame; any other frame gets the full pass,
        small-tag reading included.

        ``lens``: the camera's distortion, when it has any; the edge fit then runs where the tag's
        edges are straight (:class:`refine.Lens`)."""
        gray = to_gray(image)
        h, w = gray.shape
        self.frames_searched += 1
        reads = self._first_pass(gray, lens) if self.close_view else None
        if reads is not None:
            self.first_pass_frames += 1
            self.small_tag_skips += 1  # settled without the full pass, so without small-tag reading
        else:
            reads = self._run(gray, self._decimation_for(gray), lens)
        found = _one_per_id([d for d in reads if not touches_border(d.corners, w, h)])
        self.close_view = self._enough_well_seen(found)
        return found

    def detect_regions(
        self, image: np.ndarray, regions: Sequence[tuple[int, np.ndarray]], lens: Lens | None = None
    ) -> list[TagDetection]:
        """Search crops for specific tags: ``regions`` holds ``(tag_id, predicted corners (4, 2))``.

        Each crop is the predicted quad's bounding box grown by its own size, searched at full
        resolution (×2 upscaled when the tag is small). Only the wanted id is kept from each crop,
        and only when it lies wholly inside both the crop and the frame.
        """
        gray = to_gray(image)
        h, w = gray.shape
        out: list[TagDetection] = []
        for tag_id, predicted in regions:
            lo, hi = predicted.min(axis=0), predicted.max(axis=0)
            extent = float(max(hi - lo))
            if not np.isfinite(extent) or extent < 4.0:
                continue
            x0, y0 = np.floor(lo - extent).astype(int)
            x1, y1 = np.ceil(hi + extent).astype(int)
            x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
            if x1 - x0 < 8 or y1 - y0 < 8:
                continue
            crop = np.ascontiguousarray(gray[y0:y1, x0:x1])
            scale = 2.0 if extent < UPSCALE_BELOW_PX else 1.0
            if scale != 1.0:
                crop = cv2.resize(crop, None, fx=scale, fy=scale, interpolation=cv2.INTER_CUBIC)
            ch, cw = crop.shape
            for d in self._run(crop, 1.0):
                if d.tag_id != tag_id or touches_border(d.corners, cw, ch):
                    continue
                # Back to frame pixels: crop pixel centre U ↔ frame (U + 0.5)/scale − 0.5 + offset.
                corners = (d.corners + 0.5) / scale - 0.5 + np.array([x0, y0], dtype=np.float64)
                if lens is not None and self.method == "opencv":
                    corners = refine_corners(gray, [corners], 1, lens)[0]  # the crop's fit knew no distortion
                if not touches_border(corners, w, h):
                    out.append(TagDetection(d.tag_id, corners, d.detector, d.decision_margin, d.hamming))
                break
        return out


def _inside_any(points: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(N,) bool: whether each of ``points`` (N, 2) lies inside any of the convex ``quads`` (M, 4, 2)."""
    edges = np.roll(quads, -1, axis=1) - quads  # (M, 4, 2)
    rel = points[:, None, None, :] - quads[None, :, :, :]  # (N, M, 4, 2)
    cross = edges[None, ..., 0] * rel[..., 1] - edges[None, ..., 1] * rel[..., 0]  # (N, M, 4)
    # Inside a convex quad: on the same side of all four edges, whichever the winding.
    return ((cross >= 0).all(axis=2) | (cross <= 0).all(axis=2)).any(axis=1)


def _one_per_id(dets: list[TagDetection]) -> list[TagDetection]:
    """Keep one detection per tag id (a site has each id once; a duplicate is a mis-decode)."""
    best: dict[int, TagDetection] = {}
    for d in dets:
        if d.tag_id not in best or d.decision_margin > best[d.tag_id].decision_margin:
            best[d.tag_id] = d
    return sorted(best.values(), key=lambda d: d.tag_id)
