"""A top-down occupancy grid of a site, for motion planning.

Cell ``(row, col)`` covers ``[x0 + col*res, x0 + (col+1)*res) × [y0 + row*res, y0 + (row+1)*res)``
with ``origin = (x0, y0)``; ``occupied`` has shape ``(ny, nx)`` and row = y index (row 0 is the
southmost). A cell is occupied when it lies outside every room, or when any part of it overlaps
a wall's solid box or a door leaf (conservative, so thin walls and leaves never leak).
A door's leaf blocks its gap unless the door is listed in ``open_doors``; an open door's leaf
stands in its swing room at 90° and is an obstacle there. With ``inflate = r`` a cell is also
occupied when its centre is closer than ``r`` to an occupied cell's edge (so a robot of radius
``r`` may have its centre on any free cell).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .model import Site

Box = tuple[float, float, float, float]


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    resolution: float
    origin: tuple[float, float]
    occupied: np.ndarray  # bool, shape (ny, nx), read-only
    inflation: float = 0.0

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupied.shape  # type: ignore[return-value]

    def world_to_cell(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of the cell containing (x, y); may lie outside the grid."""
        return (math.floor((y - self.origin[1]) / self.resolution), math.floor((x - self.origin[0]) / self.resolution))

    def cell_to_world(self, row: int, col: int) -> tuple[float, float]:
        """Centre of cell (row, col)."""
        return (self.origin[0] + (col + 0.5) * self.resolution, self.origin[1] + (row + 0.5) * self.resolution)

    def in_bounds(self, row: int, col: int) -> bool:
        return 0 <= row < self.occupied.shape[0] and 0 <= col < self.occupied.shape[1]

    def is_free(self, x: float, y: float) -> bool:
        """False outside the grid or on an occupied cell."""
        row, col = self.world_to_cell(x, y)
        return self.in_bounds(row, col) and not bool(self.occupied[row, col])


def _cells(lo: float, hi: float, start: float, res: float, n: int) -> slice:
    """Indices of cells overlapping the open interval (lo, hi) by a positive length."""
    first = math.floor((lo - start) / res + 1e-9)
    last = math.ceil((hi - start) / res - 1e-9)
    return slice(max(first, 0), min(max(last, 0), n))


def _fill(grid: np.ndarray, box: Box, origin: tuple[float, float], res: float, value: bool) -> None:
    x0, y0, x1, y1 = box
    ny, nx = grid.shape
    grid[_cells(y0, y1, origin[1], res, ny), _cells(x0, x1, origin[0], res, nx)] = value


def _fill_centres(grid: np.ndarray, box: Box, origin: tuple[float, float], res: float, value: bool) -> None:
    """Set cells whose centre lies in ``box`` (edges included)."""
    x0, y0, x1, y1 = box
    ny, nx = grid.shape
    cols = slice(
        max(math.ceil((x0 - origin[0]) / res - 0.5 - 1e-9), 0),
        min(math.floor((x1 - origin[0]) / res - 0.5 + 1e-9) + 1, nx),
    )
    rows = slice(
        max(math.ceil((y0 - origin[1]) / res - 0.5 - 1e-9), 0),
        min(math.floor((y1 - origin[1]) / res - 0.5 + 1e-9) + 1, ny),
    )
    grid[rows, cols] = value


def inflate_occupied(occupied: np.ndarray, resolution: float, radius: float) -> np.ndarray:
    """Occupied cells grown by ``radius`` metres (Euclidean distance transform, so it is fast)."""
    import cv2  # only the inflating path needs OpenCV

    free = (~occupied).astype(np.uint8)
    # Pad with obstacles so the grid border counts as occupied, as outside the building is.
    padded = np.pad(free, 1, constant_values=0)
    dist = cv2.distanceTransform(padded, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
    # dist is centre-to-centre in cells; the obstacle's near edge is half a cell closer.
    return occupied | ((dist - 0.5) * resolution < radius)


def build_grid(site: Site, resolution: float, open_doors: frozenset[str], inflate: float) -> OccupancyGrid:
    if not (resolution > 0 and math.isfinite(resolution)):
        raise ValueError(f"occupancy_grid: resolution must be a positive number, got {resolution!r}")
    if not (inflate >= 0 and math.isfinite(inflate)):
        raise ValueError(f"occupancy_grid: inflate must be a non-negative number, got {inflate!r}")
    unknown = sorted(d for d in open_doors if d not in site.door_leaves)
    if unknown:
        raise ValueError(
            f"occupancy_grid: open_doors: unknown door(s) {', '.join(unknown)} (doors are "
            f"{', '.join(site.door_leaves)})"
        )
    bx0, by0, bx1, by1 = site.bounds
    margin = site.params.wall_thickness / 2.0 + resolution
    origin = (bx0 - margin, by0 - margin)
    # Rounded first: 8.3 / 0.1 is 83.00000000000001 in floating point, which is 83 cells, not 84.
    nx = math.ceil(round((bx1 - bx0 + 2 * margin) / resolution, 6))
    ny = math.ceil(round((by1 - by0 + 2 * margin) / resolution, 6))
    occupied = np.ones((ny, nx), dtype=bool)
    for room in site.rooms.values():
        _fill_centres(occupied, room.rect, origin, resolution, False)
    for wall in site.walls:
        _fill(occupied, wall.box, origin, resolution, True)
    for door, leaf in site.door_leaves.items():
        _fill(occupied, leaf.box(open=door in open_doors), origin, resolution, True)
    if inflate > 0:
        occupied = inflate_occupied(occupied, resolution, inflate)
    occupied.setflags(write=False)
    return OccupancyGrid(resolution=float(resolution), origin=origin, occupied=occupied, inflation=float(inflate))
