"""AprilTag 36h11 images and corner naming, shared by the simulator, the AR client and the tag sheet.

Conventions (DESIGN §3):

* The tag image is the official AprilRobotics ``tag36h11`` image (``apriltag-imgs``,
  ``tag36h11/tag36_11_<id>.png``) in its upright orientation. That image is 10×10 modules: a
  1-module white quiet zone around an 8×8-module black-bordered square (6×6 data modules inside a
  1-module black frame). A landmark's ``size`` is the edge of that black 8×8 square.
* OpenCV 5.0's ``cv2.aruco.generateImageMarker(DICT_APRILTAG_36h11, id, 8)`` draws the 8×8 black
  square turned 180° from the official image, so :func:`tag_image` turns it back. The tests check
  the result pixel for pixel against the AprilTag 3 C library's own ``apriltag_to_image`` and
  decode it with ``pupil-apriltags``.
* "Upright" means the official image's top row is up (+z on a wall). The corners of a tag are named
  top-left (TL), top-right (TR), bottom-right (BR), bottom-left (BL) of the upright image seen from
  the front, in that order (clockwise on screen). :func:`opencv_corners` and
  :func:`apriltag_corners` reorder each detector's output to that order.
* Pixel coordinates follow OpenCV: the centre of pixel (u, v) is at (u, v). The AprilTag 3 library
  reports corners 0.5 px further right and down (its pixel centres are at +0.5), so
  :func:`apriltag_corners` shifts them by −0.5 px.
"""

from __future__ import annotations

import cv2
import numpy as np

#: Modules across the black square (6×6 data + a 1-module black frame on each side).
BLACK_MODULES = 8
#: Corner names in the order every function here returns them.
CORNER_NAMES: tuple[str, str, str, str] = ("TL", "TR", "BR", "BL")

_DICTIONARY = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
#: Number of distinct ids in the family (0 .. NUM_TAGS-1).
NUM_TAGS: int = int(_DICTIONARY.bytesList.shape[0])

# Index permutations mapping a detector's corner list to TL, TR, BR, BL.
# OpenCV lists the corners of the image its generator draws (TL, TR, BR, BL of *that* image); since
# that image is the official one turned 180°, its TL is the official BR and so on.
_OPENCV_TO_NAMED = (2, 3, 0, 1)
# The AprilTag library lists tag-frame corners (-1,1), (1,1), (1,-1), (-1,-1) with tag y pointing
# down the official image: BL, BR, TR, TL.
_APRILTAG_TO_NAMED = (3, 2, 1, 0)
# AprilTag's pixel centres sit at +0.5 relative to OpenCV's.
_APRILTAG_PIXEL_OFFSET = -0.5


def tag_image(tag_id: int, module_px: int = 10, border_modules: int = 1) -> np.ndarray:
    """The official upright tag36h11 image of ``tag_id`` as uint8 grayscale (0 black, 255 white).

    The image is the 8×8-module black square surrounded by ``border_modules`` white modules of
    quiet zone, each module ``module_px`` pixels: ``(8 + 2·border_modules)·module_px`` pixels square.
    ``border_modules=1`` reproduces the official PNG exactly (its own 1-module white border counts
    as that one module); ``0`` gives the bare black square. Module edges are pixel-exact (nearest
    neighbour), so a renderer sampling this texture sees crisp modules.
    """
    if not 0 <= tag_id < NUM_TAGS:
        raise ValueError(f"tag id {tag_id} is outside tag36h11 (0..{NUM_TAGS - 1})")
    if module_px < 1:
        raise ValueError(f"module_px must be >= 1, got {module_px}")
    if border_modules < 0:
        raise ValueError(f"border_modules must be >= 0, got {border_modules}")
    # One pixel per module first, then scale: generateImageMarker resamples non-multiples unevenly.
    square = cv2.aruco.generateImageMarker(_DICTIONARY, tag_id, BLACK_MODULES)
    square = np.rot90(square, 2)
    modules = np.pad(square, border_modules, mode="constant", constant_values=255)
    image = np.kron(modules, np.ones((module_px, module_px), dtype=np.uint8))
    return np.ascontiguousarray(image, dtype=np.uint8)


def quad_edge(size: float, border_modules: int = 1) -> float:
    """Edge, in metres, of the whole :func:`tag_image` on the wall when its black square is ``size``."""
    return size * (BLACK_MODULES + 2 * border_modules) / BLACK_MODULES


def tag_image_corners(module_px: int = 10, border_modules: int = 1) -> np.ndarray:
    """Pixel positions (OpenCV convention) of the black square's TL, TR, BR, BL in :func:`tag_image`.

    These are the outer corners of the black square, i.e. pixel *edges*: the first black pixel's
    centre is at ``border_modules·module_px`` and its outer edge half a pixel before that.
    """
    lo = border_modules * module_px - 0.5
    hi = (border_modules + BLACK_MODULES) * module_px - 0.5
    return np.array([[lo, lo], [hi, lo], [hi, hi], [lo, hi]], dtype=np.float64)


def opencv_corners(corners: np.ndarray) -> np.ndarray:
    """One OpenCV ArUco detection's corners (shape (1,4,2) or (4,2)) as TL, TR, BR, BL, float64 (4,2)."""
    c = np.asarray(corners, dtype=np.float64).reshape(4, 2)
    return c[list(_OPENCV_TO_NAMED)]


def apriltag_corners(corners: np.ndarray) -> np.ndarray:
    """One pupil-apriltags detection's ``corners`` (4,2) as TL, TR, BR, BL in OpenCV pixel convention."""
    c = np.asarray(corners, dtype=np.float64).reshape(4, 2)
    return c[list(_APRILTAG_TO_NAMED)] + _APRILTAG_PIXEL_OFFSET


def named_corners(corners: np.ndarray, detector: str) -> np.ndarray:
    """Dispatch to :func:`opencv_corners` (``"opencv"``) or :func:`apriltag_corners` (``"apriltag"``)."""
    if detector == "opencv":
        return opencv_corners(corners)
    if detector == "apriltag":
        return apriltag_corners(corners)
    raise ValueError(f"unknown detector {detector!r} (expected 'opencv' or 'apriltag')")
