"""Per-robot colours, shared by every view of the robots (simulator bodies, AR overlay, maps).

A robot's colour follows from its index among the site's robot ids in sorted order, so the
simulator, the AR client and the tablet map agree on which robot is orange without talking.
Hues advance by the golden ratio (each new colour lands in the widest remaining gap), saturated and
bright enough to stand out against grey walls and floors.
"""

from __future__ import annotations

import colorsys
from collections.abc import Iterable

#: Hue of robot 0, and the step between consecutive robots (golden-ratio conjugate).
FIRST_HUE = 0.08
HUE_STEP = 0.618034
SATURATION = 0.85
VALUE = 1.0

RGB = tuple[int, int, int]


def _rgb(hue: float) -> RGB:
    r, g, b = colorsys.hsv_to_rgb(hue % 1.0, SATURATION, VALUE)
    return (int(r * 255), int(g * 255), int(b * 255))


def robot_color(index: int) -> RGB:
    """The colour (r, g, b), 0–255, of the robot at ``index`` in the sorted robot ids."""
    if index < 0:
        raise ValueError(f"robot colour index must be >= 0, got {index}")
    return _rgb(FIRST_HUE + index * HUE_STEP)


def robot_colors(robot_ids: Iterable[str]) -> dict[str, RGB]:
    """Every robot's colour, by id: :func:`robot_color` of its index among the sorted ids."""
    return {rid: robot_color(i) for i, rid in enumerate(sorted(robot_ids))}


def unlisted_robot_color(robot_id: str) -> RGB:
    """A stable colour for a robot the site file does not list (derived from its id's characters)."""
    return _rgb(sum(map(ord, robot_id)) * HUE_STEP)
