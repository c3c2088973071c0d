"""World state → 2-D drawing primitives for one camera pose (the Visualizer of paper §III-D).

What is drawn (layers in brackets, so a thin client can toggle them):

* each robot as a wireframe cylinder (its footprint radius, ``AVATAR_HEIGHT`` tall) with a heading
  arrow on top and its id (and status) as a label, in the robot's colour [``robot:<rid>``];
* its Intent from "now" on as a floor-level path with direction arrows every ``ARROW_SPACING`` m
  and time marks (``+10s`` …) every ``TIME_MARK_STEP`` s, ending in a goal ring [``intent:<rid>``];
* every door's leaf, open or closed (green/red; grey while its state is unknown) [``door``];
* pose quality and latency [``status``].

Anything a wall hides from the camera (:mod:`visibility`) keeps its colour but gets style ``xray``
(drawn dashed and translucent). Robot avatars are classified by their centre, paths and door leaves
piece by piece. 3-D geometry goes through :meth:`Projector.project_polyline`, which clips at the
near plane, so nothing behind the tablet is mirrored into view. Without a pose only the status
(and the UI) are drawn: no world geometry is ever placed from a guessed pose.
"""

from __future__ import annotations

import colorsys
import math
from collections.abc import Iterable

import numpy as np

from protocol.messages import Primitive

from .localize import Localization
from .project import Projector, clip_polyline
from .visibility import Occluders, resample, split_runs
from .world import WorldSnapshot

AVATAR_HEIGHT = 0.45  # metres
AVATAR_SEGMENTS = 24  # polygon sides of the cylinder's rings
PATH_Z = 0.01  # paths float 1 cm above the floor so they are not lost in it
ARROW_SPACING = 1.0  # metres between direction arrows along a path
ARROW_LENGTH = 0.3
TIME_MARK_STEP = 10.0  # seconds between time marks
MAX_TIME_MARKS = 8
DOOR_HEIGHT = 2.0
TEXT_PX = 16.0  # label height in pixels

DOOR_OPEN = [60, 200, 80, 255]
DOOR_CLOSED = [230, 60, 50, 255]
DOOR_UNKNOWN = [160, 160, 160, 255]
STATUS_OK = [80, 230, 80, 255]
STATUS_WARN = [255, 190, 40, 255]
STATUS_LOST = [255, 70, 60, 255]


def robot_colours(robot_ids: Iterable[str]) -> dict[str, list[int]]:
    """Well-separated RGBA colours, stable for a given set of ids (golden-ratio hue steps)."""
    out = {}
    for i, rid in enumerate(sorted(robot_ids)):
        r, g, b = colorsys.hsv_to_rgb((0.08 + i * 0.618034) % 1.0, 0.85, 1.0)
        out[rid] = [int(r * 255), int(g * 255), int(b * 255), 255]
    return out


class OverlayBuilder:
    """Builds the world primitives for frames of one site."""

    def __init__(self, site) -> None:  # noqa: ANN001 (protocol.site.Site)
        self.site = site
        self.radius = site.params.robot_radius
        self.colours = robot_colours(site.robots)
        self._occluders: dict[frozenset[str], Occluders] = {}
        angles = np.linspace(0.0, 2.0 * np.pi, AVATAR_SEGMENTS + 1)
        self._ring = np.stack([np.cos(angles), np.sin(angles)], axis=1)

    def colour(self, rid: str) -> list[int]:
        if rid not in self.colours:  # a robot the site file does not list: derive a colour from its id
            hue = (sum(map(ord, rid)) * 0.618034) % 1.0
            r, g, b = colorsys.hsv_to_rgb(hue, 0.85, 1.0)
            self.colours[rid] = [int(r * 255), int(g * 255), int(b * 255), 255]
        return self.colours[rid]

    def occluders(self, open_doors: set[str]) -> Occluders:
        key = frozenset(open_doors)
        occ = self._occluders.get(key)
        if occ is None:
            occ = Occluders.from_site(self.site, key)
            self._occluders[key] = occ
        return occ

    # ------------------------------------------------------------------ entry point

    def world_primitives(self, projector: Projector, world: WorldSnapshot) -> list[Primitive]:
        """Robots, intents and doors as seen through ``projector`` (a pose must be known)."""
        occ = self.occluders(world.open_doors)
        eye = projector.pose.position
        prims: list[Primitive] = []
        for did in sorted(self.site.door_leaves):
            prims += self._door(projector, occ, eye, did, world)
        for rid in sorted(world.intents):
            prims += self._intent(projector, occ, eye, rid, world)
        for rid in sorted(world.robots):
            prims += self._robot(projector, occ, eye, rid, world)
        return prims

    # ------------------------------------------------------------------ pieces

    def _hidden(self, occ: Occluders, eye: np.ndarray, points_xy: np.ndarray) -> np.ndarray:
        """Hidden flags of floor points, each tested from just in front of itself (towards the eye).

        The nudge keeps a point that sits on a wall line (a door leaf, a robot at a jamb) from
        being hidden by that very wall.
        """
        pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        towards = eye[:2] - pts
        dist = np.linalg.norm(towards, axis=1, keepdims=True)
        nudged = pts + towards / np.maximum(dist, 1e-9) * np.minimum(0.06, dist * 0.5)
        return occ.blocked_many(eye[:2], nudged, eye_z=float(eye[2]))

    def _lines(
        self, projector: Projector, pts3: np.ndarray, *, colour, style: str, layer: str, width: float = 2.0
    ) -> list[Primitive]:
        out = []
        box = _keep_box(projector)
        for piece in projector.project_polyline(pts3):
            for part in clip_polyline(piece, box):
                out.append(
                    Primitive(
                        kind="polyline", points=part.tolist(), color=list(colour), width=width, style=style, layer=layer
                    )
                )
        return out

    def _text(
        self, projector: Projector, at3: np.ndarray, text: str, colour, style: str, layer: str
    ) -> list[Primitive]:
        uv, front = projector.project_points(np.asarray(at3).reshape(1, 3))
        if not front[0] or not _in_box(uv, _keep_box(projector)):
            return []
        return [
            Primitive(
                kind="text",
                points=[uv[0].tolist()],
                text=text,
                color=list(colour),
                radius=TEXT_PX,
                style=style,
                layer=layer,
            )
        ]

    def _arrow(
        self,
        projector: Projector,
        tail3: np.ndarray,
        head3: np.ndarray,
        colour,
        style: str,
        layer: str,
        width: float = 2.0,
    ) -> list[Primitive]:
        uv, front = projector.project_points(np.stack([tail3, head3]))
        if not front.all() or not _in_box(uv, _keep_box(projector)):
            return []
        return [Primitive(kind="arrow", points=uv.tolist(), color=list(colour), width=width, style=style, layer=layer)]

    def _robot(
        self, projector: Projector, occ: Occluders, eye: np.ndarray, rid: str, world: WorldSnapshot
    ) -> list[Primitive]:
        rs = world.robots[rid]
        layer = f"robot:{rid}"
        colour = self.colour(rid)
        style = "xray" if self._hidden(occ, eye, np.array([[rs.x, rs.y]]))[0] else "solid"
        c = np.array([rs.x, rs.y])
        ring = c + self.radius * self._ring
        bottom = np.column_stack([ring, np.zeros(len(ring))])
        top = np.column_stack([ring, np.full(len(ring), AVATAR_HEIGHT)])
        prims = self._lines(projector, bottom, colour=colour, style=style, layer=layer)
        prims += self._lines(projector, top, colour=colour, style=style, layer=layer)
        for k in range(0, AVATAR_SEGMENTS, AVATAR_SEGMENTS // 4):  # four vertical edges
            prims += self._lines(projector, np.stack([bottom[k], top[k]]), colour=colour, style=style, layer=layer)
        heading = np.array([math.cos(rs.theta), math.sin(rs.theta)])
        tail = np.array([*c, AVATAR_HEIGHT])
        head = np.array([*(c + 1.5 * self.radius * heading), AVATAR_HEIGHT])
        prims += self._arrow(projector, tail, head, colour, style, layer, width=3.0)
        label = rid if not rs.state else f"{rid}: {rs.state.replace('_', ' ')}"
        prims += self._text(projector, np.array([rs.x, rs.y, AVATAR_HEIGHT + 0.15]), label, colour, style, layer)
        return prims

    def _intent(
        self, projector: Projector, occ: Occluders, eye: np.ndarray, rid: str, world: WorldSnapshot
    ) -> list[Primitive]:
        rows = world.intents[rid]
        if len(rows) == 0:
            return []
        rows = _from_now(rows, world.now)
        if len(rows) < 2:
            return []
        layer = f"intent:{rid}"
        colour = self.colour(rid)
        pts, frac = resample(rows[:, 1:3])
        times = np.interp(frac, np.arange(len(rows)), rows[:, 0])
        hidden = self._hidden(occ, eye, pts)
        prims: list[Primitive] = []
        for is_hidden, piece in split_runs(pts, hidden):
            pts3 = np.column_stack([piece, np.full(len(piece), PATH_Z)])
            prims += self._lines(
                projector, pts3, colour=colour, style="xray" if is_hidden else "solid", layer=layer, width=3.0
            )
        # Direction arrows by arc length, time marks by time.
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        arc = np.concatenate([[0.0], np.cumsum(seg)])
        for s in np.arange(ARROW_SPACING / 2.0, arc[-1] - ARROW_LENGTH, ARROW_SPACING):
            i = int(np.searchsorted(arc, s))
            j = int(np.searchsorted(arc, s + ARROW_LENGTH))
            j = min(j, len(pts) - 1)
            if j <= i:
                continue
            style = "xray" if hidden[i] else "solid"
            prims += self._arrow(
                projector, np.array([*pts[i], PATH_Z]), np.array([*pts[j], PATH_Z]), colour, style, layer, width=3.0
            )
        first = math.floor(world.now / TIME_MARK_STEP + 1.0) * TIME_MARK_STEP
        for k, t in enumerate(np.arange(first, times[-1], TIME_MARK_STEP)):
            if k >= MAX_TIME_MARKS:
                break
            i = int(np.clip(np.searchsorted(times, t), 0, len(pts) - 1))
            style = "xray" if hidden[i] else "solid"
            p3 = np.array([*pts[i], PATH_Z])
            uv, front = projector.project_points(p3.reshape(1, 3))
            if front[0] and _in_box(uv, _keep_box(projector)):
                prims.append(
                    Primitive(
                        kind="circle",
                        points=[uv[0].tolist()],
                        radius=4.0,
                        width=0.0,
                        color=list(colour),
                        style=style,
                        layer=layer,
                    )
                )
                prims += self._text(projector, p3, f"+{t - world.now:.0f}s", colour, style, layer)
        # The goal: a ring on the floor where the path ends.
        goal = np.column_stack([pts[-1] + 0.6 * self.radius * self._ring, np.full(len(self._ring), PATH_Z)])
        prims += self._lines(
            projector, goal, colour=colour, style="xray" if hidden[-1] else "solid", layer=layer, width=2.0
        )
        return prims

    def _door(
        self, projector: Projector, occ: Occluders, eye: np.ndarray, did: str, world: WorldSnapshot
    ) -> list[Primitive]:
        leaf = self.site.door_leaves[did]
        state = world.doors.get(did)
        is_open = bool(state and state.open)
        colour = DOOR_UNKNOWN if state is None else (DOOR_OPEN if is_open else DOOR_CLOSED)
        hinge, tip = np.array(leaf.hinge), np.array(leaf.tip(open=is_open))
        # Test the leaf against the other walls only: a closed leaf must not hide itself.
        others = self.occluders(world.open_doors | {did})
        mid = (hinge + tip) / 2.0
        style = "xray" if self._hidden(others, eye, mid.reshape(1, 2))[0] else "solid"
        outline = np.array([[*hinge, 0.0], [*tip, 0.0], [*tip, DOOR_HEIGHT], [*hinge, DOOR_HEIGHT], [*hinge, 0.0]])
        prims = self._lines(projector, outline, colour=colour, style=style, layer="door")
        word = "?" if state is None else ("open" if is_open else "closed")
        prims += self._text(projector, np.array([*mid, DOOR_HEIGHT + 0.1]), f"{did}: {word}", colour, style, "door")
        return prims


def _keep_box(projector: Projector) -> tuple[float, float, float, float]:
    """Primitives are kept within one image size around the image (off-screen beyond that)."""
    w, h = projector.K.width, projector.K.height
    return (-w, -h, 2.0 * w, 2.0 * h)


def _in_box(uv: np.ndarray, box: tuple[float, float, float, float]) -> bool:
    x0, y0, x1, y1 = box
    return bool(((uv[:, 0] >= x0) & (uv[:, 0] <= x1) & (uv[:, 1] >= y0) & (uv[:, 1] <= y1)).all())


def _from_now(rows: np.ndarray, now: float) -> np.ndarray:
    """The trajectory from ``now`` on, starting with the interpolated point at ``now``."""
    t = rows[:, 0]
    if now <= t[0]:
        return rows
    if now >= t[-1]:
        return rows[-1:]
    i = int(np.searchsorted(t, now, side="right"))
    s = (now - t[i - 1]) / max(t[i] - t[i - 1], 1e-9)
    start = rows[i - 1] + s * (rows[i] - rows[i - 1])
    start[0] = now
    return np.vstack([start, rows[i:]])


def status_primitives(loc: Localization, latency: float, width: int, height: int) -> list[Primitive]:
    """Pose quality and latency as text in the top-left corner [``status``]."""
    if loc.ok:
        colour = STATUS_WARN if loc.ambiguous or loc.rmse_px > 1.5 else STATUS_OK
        line = f"pose: {len(loc.tags)} tag{'s' if len(loc.tags) != 1 else ''}, RMSE {loc.rmse_px:.2f} px"
        if loc.ambiguous:
            line += " (ambiguous)"
        if loc.rejected:
            line += f", rejected {loc.rejected}"
    else:
        colour = STATUS_LOST
        age = "never localised" if loc.lost_age is None else f"last pose {loc.lost_age:.1f} s ago"
        line = f"LOST ({age}): {loc.reason}"
    lines = [line, f"latency {latency * 1000.0:.0f} ms"]
    size = max(14.0, height / 36.0)
    return [
        Primitive(
            kind="text",
            points=[[10.0, 10.0 + size * (k + 1) * 1.3]],
            text=txt,
            color=list(colour),
            radius=size,
            layer="status",
        )
        for k, txt in enumerate(lines)
    ]
