"""What the detector skips to stay fast, and that skipping loses nothing it needs."""

from __future__ import annotations

import numpy as np
import pytest

from services.ar_client import refine
from services.ar_client.detect import _inside_any
from services.ar_client.draw import DASH_OFF, DASH_ON, _dashes


@pytest.mark.parametrize("winding", [1, -1])
def test_inside_any_holds_for_either_winding(winding: int) -> None:
    square = np.array([[10.0, 10.0], [50.0, 12.0], [48.0, 52.0], [8.0, 50.0]])[::winding]
    other = square + 100.0
    points = np.array([[30.0, 30.0], [130.0, 130.0], [60.0, 30.0], [30.0, 5.0], [90.0, 90.0]])
    inside = _inside_any(points, np.array([square, other]))
    assert inside.tolist() == [True, True, False, False, False]


def test_only_small_tags_get_a_second_edge_fit(monkeypatch: pytest.MonkeyPatch) -> None:
    sizes: list[list[float]] = []
    real = refine.refine_once

    def counting(gray, quads, lens=None):  # noqa: ANN001, ANN202
        sizes.append([refine._module_px(q) * 8.0 for q in quads])
        return real(gray, quads, lens)

    monkeypatch.setattr(refine, "refine_once", counting)
    gray = np.full((200, 300), 200, np.uint8)
    gray[20:100, 20:100] = 20  # an 80-px square: reach already at its cap after one pass
    gray[130:150, 200:220] = 20  # a 20-px square: its profiles are shorter than the error a pass fixes
    big = np.array([[20.0, 20.0], [99.0, 20.0], [99.0, 99.0], [20.0, 99.0]])
    small = np.array([[200.0, 130.0], [219.0, 130.0], [219.0, 149.0], [200.0, 149.0]])
    out = refine.refine_corners(gray, [big, small], passes=3)
    assert len(out) == 2
    assert len(sizes) == 3 and len(sizes[0]) == 2
    assert all(len(s) == 1 and s[0] < 30.0 for s in sizes[1:])  # later passes: the small square only
    assert refine.refine_corners(gray, [big], passes=0)[0] is big


def test_dashes_follow_the_pattern_across_joints_and_skip_what_is_off_screen() -> None:
    period = DASH_ON + DASH_OFF
    line = np.array([[0.0, 10.0], [3.0 * period, 10.0], [3.0 * period, 10.0 + 2.0 * period]])
    dashes = _dashes(line, 1000, 1000)
    assert dashes.shape == (5, 2, 2)
    lengths = np.hypot(*(dashes[:, 1] - dashes[:, 0]).T)
    assert np.allclose(lengths, DASH_ON)
    far = np.array([[-1e6, -1e6], [-1e6 + 1.0, -1e6]])
    assert _dashes(far, 640, 480).shape == (0, 2, 2)
