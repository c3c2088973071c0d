"""The pybullet scene of a site: what the virtual tablet camera sees and what bodies may not overlap.

One :class:`World` owns one pybullet client (DIRECT by default) and passes its id on every call
(through :class:`pybullet_utils.bullet_client.BulletClient`), so several worlds can live in one
process (tests, benchmarks, a camera feed beside a snapshot). Everything is kinematic: the engine
decides where robots, leaves, objects and the human are, and the world is only told
(``resetBasePositionAndOrientation``); nothing is ever stepped.

Content, all built from the :class:`~protocol.site.Site`:

* a floor, and one box per :class:`~protocol.site.model.WallSegment` (exactly ``wall.box``,
  ``wall.height`` high), so the openings are the site's gaps; a lintel closes each gap above
  :data:`OPENING_HEIGHT` (cosmetic: it is above every robot, leaf and ray the engine cares about);
* a door leaf per door (a box of ``DoorLeaf.length`` × ``thickness`` × :data:`LEAF_HEIGHT`) turning
  about its hinge from ``closed_yaw`` (fraction 0) to ``open_yaw`` (fraction 1); human-operated
  doors have their own colour;
* each landmark as a one-sided textured quad carrying the official upright tag36h11 image
  (:func:`runtime.apriltag.tag_image`) with a white quiet zone, its black square exactly
  ``size`` and centred on the landmark position, facing its yaw. Textures go on a mesh quad, not a
  box: a box shows a quarter of the texture per face (NOTES.md);
* objects (0.2 m cubes in a darker shade of their robot's colour; a carried one rides on its
  robot's top), robots (cylinders of ``robot_radius`` with a heading bar on top and a bumper at
  the front, colours from :mod:`runtime.palette`) and the human (a figure holding a tablet, at her
  desk facing her door until told otherwise).

Names: walls are ``wall:<index in site.walls>``, lintels ``lintel:<opening id>``, door leaves
their door id, robots, objects their ids, the human ``human``, the floor ``floor``.
"""

from __future__ import annotations

import logging
import math
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from protocol.site import Site
from protocol.site.model import Landmark
from runtime.apriltag import quad_edge, tag_image
from runtime.palette import robot_colors

from .camera import CameraSpec
from .human import HUMAN_RADIUS
from .objects import CARRY_HEIGHT, FLOOR_HEIGHT

log = logging.getLogger(__name__)

RGBA = tuple[float, float, float, float]

# --- dimensions (m) -------------------------------------------------------------------------------
FLOOR_MARGIN = 1.0  # floor beyond the outermost walls, so an oblique view never sees its edge
FLOOR_DEPTH = 0.05
OPENING_HEIGHT = 2.1  # top of every door and passage; a lintel fills the wall above it
LEAF_HEIGHT = 2.08  # a leaf clears the lintel and the floor by 1 cm each
LEAF_FLOOR_GAP = 0.01
OBJECT_HALF = FLOOR_HEIGHT  # an object's centre stands FLOOR_HEIGHT above the floor: a 0.2 m cube
ROBOT_HEIGHT = CARRY_HEIGHT - OBJECT_HALF  # a carried object sits on the robot's top
HUMAN_HEIGHT = 1.7
HUMAN_HIDE_RADIUS = 0.5  # a camera this close to her axis is her own tablet: hide her from it
TAG_QUIET_MODULES = 2  # white modules around the black square (the official image has 1)
TAG_MODULE_PX = 16  # texture pixels per module: crisp module edges under nearest sampling
BLOCK_TOLERANCE = 1e-4  # penetration (m) below which touching does not count as overlapping

# --- colours (RGBA 0..1) ------------------------------------------------------------------------
FLOOR_COLOR: RGBA = (0.50, 0.50, 0.48, 1.0)
WALL_COLOR: RGBA = (0.86, 0.84, 0.80, 1.0)
LEAF_COLOR: RGBA = (0.55, 0.38, 0.22, 1.0)  # wood
HUMAN_LEAF_COLOR: RGBA = (0.10, 0.30, 0.80, 1.0)  # human-operated doors stand out
HEADING_COLOR: RGBA = (0.12, 0.12, 0.12, 1.0)
SHIRT_COLOR: RGBA = (0.20, 0.55, 0.35, 1.0)
SKIN_COLOR: RGBA = (0.87, 0.70, 0.58, 1.0)
TABLET_COLOR: RGBA = (0.10, 0.10, 0.10, 1.0)
WHITE: RGBA = (1.0, 1.0, 1.0, 1.0)
OBJECT_SHADE = 0.7  # an object is its robot's colour, darker, so a carried one stands out on the body

# --- light for ER_TINY_RENDERER: mostly ambient, so tags on every wall read alike; no specular
# highlight (it would wash out a tag's black modules), no shadows (they double the render time).
LIGHT_DIRECTION = (0.4, 0.3, 1.0)
LIGHT_AMBIENT, LIGHT_DIFFUSE, LIGHT_SPECULAR = 0.8, 0.3, 0.0

_IDENTITY = (0.0, 0.0, 0.0, 1.0)
_HIDDEN = (0.0, 0.0, -50.0)  # far below the floor: out of every view


def _yaw_quat(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))


def _rgba(rgb: tuple[int, int, int]) -> RGBA:
    return (rgb[0] / 255.0, rgb[1] / 255.0, rgb[2] / 255.0, 1.0)


def _shade(color: RGBA, factor: float) -> RGBA:
    return (color[0] * factor, color[1] * factor, color[2] * factor, color[3])


def human_at_desk(site: Site) -> tuple[float, float, float]:
    """The human at her desk facing the nearest door she operates (any door of her room if none),
    as the human model has her while she works: (x, y, yaw)."""
    hx, hy = site.human.position
    mine = [o for o in site.doors.values() if site.human.room in o.rooms]
    doors = [o for o in mine if o.human_operated] or mine
    if not doors:
        return hx, hy, 0.0
    cx, cy = min((o.center for o in doors), key=lambda c: math.dist(c, (hx, hy)))
    return hx, hy, math.atan2(cy - hy, cx - hx)


def _angle_diff(a: float, b: float) -> float:
    """a − b wrapped into (−π, π]."""
    return math.atan2(math.sin(a - b), math.cos(a - b))


@dataclass
class _Robot:
    body: int
    pose: tuple[float, float, float]


class World:
    """A site in pybullet, kinematic; see the module docstring."""

    def __init__(self, site: Site, *, connection: str = "direct") -> None:
        modes = {"direct": pybullet.DIRECT, "gui": pybullet.GUI}
        if connection not in modes:
            raise ValueError(f"connection must be one of {sorted(modes)}, got {connection!r}")
        self.site = site
        self._pb: BulletClient | None = BulletClient(connection_mode=modes[connection])
        # The pybullet client id BulletClient adds to every call (it has no public accessor).
        self.client: int = self._pb._client
        self._names: dict[int, str] = {}  # body id -> name
        self._bodies: dict[str, int] = {}  # name -> body id
        self.wall_names: list[str] = []
        self.lintel_names: list[str] = []
        self._robots: dict[str, _Robot] = {}
        self._doors: dict[str, int] = {}
        self._door_fraction: dict[str, float] = {}
        self._objects: dict[str, int] = {}
        self._carrier: dict[str, str | None] = {}
        self._landmarks: dict[int, int] = {}  # tag id -> body
        self._quads: dict[int, np.ndarray] = {}  # tag id -> quad vertices (4, 3) in its body frame
        self._quad_scale: dict[int, float] = {}  # tag id -> black square edge / quad edge
        self._human = -1
        self._human_pose: tuple[float, float, float] = human_at_desk(site)
        self._colors = {rid: _rgba(c) for rid, c in robot_colors(site.robots).items()}
        # A leaf never pokes above a low wall.
        self._leaf_height = min(LEAF_HEIGHT, site.params.wall_height - 2 * LEAF_FLOOR_GAP)
        try:
            self._build()
        except BaseException:
            self.close()  # no pybullet client left behind by a half-built world
            raise

    # ------------------------------------------------------------------ ids

    @property
    def robot_ids(self) -> list[str]:
        return list(self._robots)

    @property
    def door_ids(self) -> list[str]:
        return list(self._doors)

    @property
    def object_ids(self) -> list[str]:
        return list(self._objects)

    @property
    def landmark_ids(self) -> list[int]:
        return list(self._landmarks)

    @property
    def names(self) -> list[str]:
        """Every named body in the scene, in creation order."""
        return list(self._bodies)

    def body(self, name: str) -> int:
        """The pybullet body id of a named thing (see the module docstring for names)."""
        try:
            return self._bodies[name]
        except KeyError:
            raise KeyError(f"world of site {self.site.name!r} has nothing named {name!r}") from None

    def name_of(self, body: int) -> str:
        return self._names[body]

    # ------------------------------------------------------------------ building

    @property
    def pb(self) -> BulletClient:
        if self._pb is None:
            raise RuntimeError("this World is closed")
        return self._pb

    def _add(self, name: str, body: int) -> int:
        if body < 0:
            raise RuntimeError(f"pybullet could not create {name!r}")
        self._names[body] = name
        self._bodies[name] = body
        return body

    def _box(
        self,
        name: str,
        half: Iterable[float],
        center: Iterable[float],
        color: RGBA,
        *,
        collide: bool = True,
        yaw: float = 0.0,
    ) -> int:
        half = [float(v) for v in half]
        visual = self.pb.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=color)
        collision = self.pb.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half) if collide else -1
        body = self.pb.createMultiBody(
            baseMass=0,
            baseCollisionShapeIndex=collision,
            baseVisualShapeIndex=visual,
            basePosition=list(center),
            baseOrientation=_yaw_quat(yaw),
        )
        return self._add(name, body)

    def _build(self) -> None:
        site, p = self.site, self.site.params
        x0, y0, x1, y1 = site.bounds
        m = FLOOR_MARGIN
        self._box(
            "floor",
            ((x1 - x0) / 2 + m, (y1 - y0) / 2 + m, FLOOR_DEPTH / 2),
            ((x0 + x1) / 2, (y0 + y1) / 2, -FLOOR_DEPTH / 2),
            FLOOR_COLOR,
        )
        for i, wall in enumerate(site.walls):
            bx0, by0, bx1, by1 = wall.box
            name = f"wall:{i}"
            self._box(
                name,
                ((bx1 - bx0) / 2, (by1 - by0) / 2, wall.height / 2),
                ((bx0 + bx1) / 2, (by0 + by1) / 2, wall.height / 2),
                WALL_COLOR,
            )
            self.wall_names.append(name)
        if p.wall_height > OPENING_HEIGHT:
            for opening in site.openings.values():
                self._lintel(opening.id, opening.endpoints, opening.axis)
        for did, leaf in site.door_leaves.items():
            color = HUMAN_LEAF_COLOR if site.doors[did].human_operated else LEAF_COLOR
            self._doors[did] = self._box(
                did, (leaf.length / 2, leaf.thickness / 2, self._leaf_height / 2), (0.0, 0.0, 0.0), color
            )
            self.set_door_opening(did, 0.0)
        self._build_landmarks()
        for oid, spec in site.objects.items():
            self._objects[oid] = self._box(
                oid,
                (OBJECT_HALF,) * 3,
                (*spec.position, FLOOR_HEIGHT),
                _shade(self._colors[spec.robot], OBJECT_SHADE),
                collide=False,
            )
            self._carrier[oid] = None
        for rid, spec in site.robots.items():
            self._robots[rid] = _Robot(self._add(rid, self._robot_body(self._colors[rid])), spec.start)
            self.set_robot_pose(rid, *spec.start)
        self._human = self._add("human", self._human_body())
        self.set_human_pose(*self._human_pose)

    def _lintel(self, opening_id: str, ends: tuple[tuple[float, float], tuple[float, float]], axis: str) -> None:
        t, h = self.site.params.wall_thickness, self.site.params.wall_height
        (ax, ay), (bx, by) = ends
        half_along = (math.dist((ax, ay), (bx, by))) / 2
        half = (half_along, t / 2) if axis == "x" else (t / 2, half_along)
        name = f"lintel:{opening_id}"
        self._box(
            name,
            (*half, (h - OPENING_HEIGHT) / 2),
            ((ax + bx) / 2, (ay + by) / 2, (h + OPENING_HEIGHT) / 2),
            WALL_COLOR,
            collide=False,
        )
        self.lintel_names.append(name)

    def _build_landmarks(self) -> None:
        # pybullet loads textures only from files: write each tag image once, load it, discard it.
        with tempfile.TemporaryDirectory(prefix="arroch-tags-") as tmp:
            for landmark in self.site.landmarks:
                self._warn_if_buried(landmark)
                path = Path(tmp) / f"tag36_11_{landmark.tag:05d}.png"
                if not cv2.imwrite(str(path), tag_image(landmark.tag, TAG_MODULE_PX, TAG_QUIET_MODULES)):
                    raise RuntimeError(f"could not write the texture of tag {landmark.tag} to {path}")
                texture = self.pb.loadTexture(str(path))
                body = self._landmark_quad(landmark)
                self.pb.changeVisualShape(body, -1, textureUniqueId=texture, rgbaColor=WHITE)
                self._landmarks[landmark.tag] = body

    def _landmark_quad(self, landmark: Landmark) -> int:
        """A one-sided quad facing the landmark's yaw; corners TL, TR, BR, BL of the printed image."""
        center = np.asarray(landmark.position, dtype=float)
        black = landmark.corners()  # the black square's TL, TR, BR, BL (the site's convention)
        scale = quad_edge(landmark.size, TAG_QUIET_MODULES) / landmark.size
        local = (black - center) * scale  # the printed quad, in the body frame (body at the centre)
        self._quads[landmark.tag] = local
        self._quad_scale[landmark.tag] = 1.0 / scale
        vertices = local.tolist()
        # OpenGL texture coordinates: v = 1 is the image's top row; TL, TR, BR, BL.
        uvs = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]]
        # Counter-clockwise seen from the front (TL, BL, BR and TL, BR, TR): the face the renderer keeps.
        indices = [0, 3, 2, 0, 2, 1]
        normals = [list(landmark.normal)] * 4
        visual = self.pb.createVisualShape(
            pybullet.GEOM_MESH, vertices=vertices, indices=indices, uvs=uvs, normals=normals, rgbaColor=WHITE
        )
        body = self.pb.createMultiBody(
            baseMass=0,
            baseCollisionShapeIndex=-1,
            baseVisualShapeIndex=visual,
            basePosition=center.tolist(),
            baseOrientation=_IDENTITY,
        )
        return self._add(f"tag:{landmark.tag}", body)

    def _warn_if_buried(self, landmark: Landmark) -> None:
        """Warn about a landmark whose centre is inside a wall's solid box: the wall hides it."""
        x, y, z = landmark.position
        for i, wall in enumerate(self.site.walls):
            bx0, by0, bx1, by1 = wall.box
            if bx0 < x < bx1 and by0 < y < by1 and 0.0 < z < wall.height:
                log.warning(
                    "landmark tag %d at (%.3f, %.3f, %.3f) lies inside wall %d's thickness (box %s): the camera cannot "
                    "see it; "
                    "put it just in front of the wall's face",
                    landmark.tag,
                    x,
                    y,
                    z,
                    i,
                    wall.box,
                )
                return

    def _robot_body(self, color: RGBA) -> int:
        r = self.site.params.robot_radius
        bar = (0.5 * r, 0.035, 0.01)  # heading bar on the top, from the centre to the rim
        bumper = (0.03, 0.4 * r, 0.05)  # dark block on the front face, visible from the side
        visual = self.pb.createVisualShapeArray(
            shapeTypes=[pybullet.GEOM_CYLINDER, pybullet.GEOM_BOX, pybullet.GEOM_BOX],
            radii=[r, 0.0, 0.0],
            lengths=[ROBOT_HEIGHT, 0.0, 0.0],
            halfExtents=[[0.0] * 3, list(bar), list(bumper)],
            visualFramePositions=[
                [0.0, 0.0, ROBOT_HEIGHT / 2],
                [r - bar[0], 0.0, ROBOT_HEIGHT + bar[2]],
                [r - 0.01, 0.0, ROBOT_HEIGHT * 0.6],
            ],
        )
        collision = self.pb.createCollisionShape(
            pybullet.GEOM_CYLINDER, radius=r, height=ROBOT_HEIGHT, collisionFramePosition=[0.0, 0.0, ROBOT_HEIGHT / 2]
        )
        body = self.pb.createMultiBody(baseMass=0, baseCollisionShapeIndex=collision, baseVisualShapeIndex=visual)
        for shape, rgba in enumerate((color, HEADING_COLOR, HEADING_COLOR)):
            self.pb.changeVisualShape(body, -1, shapeIndex=shape, rgbaColor=rgba)
        return body

    def _human_body(self) -> int:
        torso = HUMAN_HEIGHT - 0.25
        head = 0.11
        tablet = (0.01, 0.12, 0.09)
        visual = self.pb.createVisualShapeArray(
            shapeTypes=[pybullet.GEOM_CYLINDER, pybullet.GEOM_SPHERE, pybullet.GEOM_BOX],
            radii=[HUMAN_RADIUS, head, 0.0],
            lengths=[torso, 0.0, 0.0],
            halfExtents=[[0.0] * 3, [0.0] * 3, list(tablet)],
            visualFramePositions=[
                [0.0, 0.0, torso / 2],
                [0.0, 0.0, HUMAN_HEIGHT - head],
                [HUMAN_RADIUS + 0.12, 0.0, 1.15],
            ],
            visualFrameOrientations=[
                list(_IDENTITY),
                list(_IDENTITY),
                list(pybullet.getQuaternionFromEuler((0.0, -0.5, 0.0))),
            ],
        )
        body = self.pb.createMultiBody(baseMass=0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=visual)
        for shape, rgba in enumerate((SHIRT_COLOR, SKIN_COLOR, TABLET_COLOR)):
            self.pb.changeVisualShape(body, -1, shapeIndex=shape, rgbaColor=rgba)
        return body

    # ------------------------------------------------------------------ state

    def set_robot_pose(self, rid: str, x: float, y: float, theta: float) -> None:
        robot = self._robot(rid)
        robot.pose = (float(x), float(y), float(theta))
        self.pb.resetBasePositionAndOrientation(robot.body, (x, y, 0.0), _yaw_quat(theta))
        for oid, carrier in self._carrier.items():
            if carrier == rid:
                self._place_carried(oid, robot.pose)

    def robot_pose(self, rid: str) -> tuple[float, float, float]:
        return self._robot(rid).pose

    def set_door_opening(self, did: str, fraction: float) -> None:
        """Turn door ``did``'s leaf: 0 closed (along the gap) … 1 fully open (``open_yaw``)."""
        if did not in self._doors:
            raise KeyError(f"site {self.site.name!r} has no door {did!r}")
        f = min(1.0, max(0.0, float(fraction)))
        leaf = self.site.door_leaves[did]
        yaw = leaf.closed_yaw + f * _angle_diff(leaf.open_yaw, leaf.closed_yaw)
        hx, hy = leaf.hinge
        center = (
            hx + leaf.length / 2 * math.cos(yaw),
            hy + leaf.length / 2 * math.sin(yaw),
            LEAF_FLOOR_GAP + self._leaf_height / 2,
        )
        self.pb.resetBasePositionAndOrientation(self._doors[did], center, _yaw_quat(yaw))
        self._door_fraction[did] = f

    def door_opening(self, did: str) -> float:
        return self._door_fraction[did]

    def set_object_pose(self, oid: str, x: float, y: float, z: float) -> None:
        """Put object ``oid``'s centre at (x, y, z) (an object on the floor: z = FLOOR_HEIGHT)."""
        self.pb.resetBasePositionAndOrientation(self._object(oid), (x, y, z), _IDENTITY)

    def attach_object(self, oid: str, rid: str | None) -> None:
        """Object ``oid`` rides on robot ``rid`` from now on (None: it stays where it is)."""
        self._object(oid)
        if rid is None:
            self._carrier[oid] = None
            return
        robot = self._robot(rid)
        self._carrier[oid] = rid
        self._place_carried(oid, robot.pose)

    def carrier(self, oid: str) -> str | None:
        self._object(oid)
        return self._carrier[oid]

    def _place_carried(self, oid: str, pose: tuple[float, float, float]) -> None:
        x, y, theta = pose
        self.pb.resetBasePositionAndOrientation(self._objects[oid], (x, y, CARRY_HEIGHT), _yaw_quat(theta))

    def set_human_pose(self, x: float, y: float, yaw: float) -> None:
        """Where the human stands and the way she faces (her tablet is in front of her)."""
        self._human_pose = (float(x), float(y), float(yaw))
        self.pb.resetBasePositionAndOrientation(self._human, (x, y, 0.0), _yaw_quat(yaw))

    def _robot(self, rid: str) -> _Robot:
        try:
            return self._robots[rid]
        except KeyError:
            raise KeyError(f"site {self.site.name!r} has no robot {rid!r}") from None

    def _object(self, oid: str) -> int:
        try:
            return self._objects[oid]
        except KeyError:
            raise KeyError(f"site {self.site.name!r} has no object {oid!r}") from None

    # ------------------------------------------------------------------ queries

    def landmark_quad(self, tag: int) -> np.ndarray:
        """World corners (4, 3) TL, TR, BR, BL of ``tag``'s textured quad, quiet zone included,
        from the pose pybullet holds for it."""
        if tag not in self._landmarks:
            raise KeyError(f"site {self.site.name!r} has no landmark with tag {tag}")
        pos, orn = self.pb.getBasePositionAndOrientation(self._landmarks[tag])
        R = np.asarray(self.pb.getMatrixFromQuaternion(orn)).reshape(3, 3)
        return np.asarray(pos) + self._quads[tag] @ R.T

    def landmark_corners(self, tag: int) -> np.ndarray:
        """World corners (4, 3) TL, TR, BR, BL of ``tag``'s black square as built (see :meth:`landmark_quad`)."""
        quad = self.landmark_quad(tag)
        center = quad.mean(axis=0)
        return center + (quad - center) * self._quad_scale[tag]

    def pose_of(self, name: str) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """(position, quaternion xyzw) of a named body, as pybullet holds it."""
        pos, orn = self.pb.getBasePositionAndOrientation(self.body(name))
        return tuple(pos), tuple(orn)

    def aabb(self, name: str) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        lo, hi = self.pb.getAABB(self.body(name))
        return tuple(lo), tuple(hi)

    def ray(self, start: Iterable[float], end: Iterable[float]) -> str | None:
        """Name of the first body with a collision shape the segment start → end hits, or None."""
        hit = self.pb.rayTest(list(start), list(end))[0]
        return None if hit[0] < 0 else self._names[hit[0]]

    def robot_blocked(self, rid: str, wall_tolerance: float = 0.0) -> str | None:
        """A wall (``wall:<i>``) or door leaf (door id) the robot's body overlaps, or None when clear.

        Exact convex-shape distances (``getClosestPoints``) between the robot's cylinder and each
        wall or leaf near it; touching (penetration under :data:`BLOCK_TOLERANCE`) does not count,
        nor reaching into a wall by up to ``wall_tolerance`` (the executor's wall guard allows a
        jamb's corner to be grazed: ``RobotConfig.wall_tolerance``).
        """
        robot = self._robot(rid)
        x, y, _ = robot.pose
        reach = self.site.params.robot_radius + 0.05
        candidates = self.wall_names + self.door_ids
        for name in candidates:
            body = self._bodies[name]
            (lx, ly, _), (hx, hy, _) = self.pb.getAABB(body)
            if x < lx - reach or x > hx + reach or y < ly - reach or y > hy + reach:
                continue  # too far for any contact: skip the exact query
            allowed = max(BLOCK_TOLERANCE, wall_tolerance if name in self.wall_names else 0.0)
            for point in self.pb.getClosestPoints(robot.body, body, distance=0.0):
                if point[8] < -allowed:  # contactDistance < 0: penetration
                    return name
        return None

    # ------------------------------------------------------------------ rendering

    def render(self, camera: CameraSpec) -> np.ndarray:
        """RGB uint8 image (height, width, 3) of the scene through ``camera`` (ER_TINY_RENDERER).

        A camera standing inside the human figure is her own tablet: she is left out of that frame
        (her arms and tablet would fill its bottom edge).
        """
        hide_human = self._camera_inside_human(camera)
        if hide_human:
            self.pb.resetBasePositionAndOrientation(self._human, _HIDDEN, _IDENTITY)
        try:
            width, height = camera.render_size
            _, _, rgba, _, _ = self.pb.getCameraImage(
                width,
                height,
                viewMatrix=camera.view_matrix(),
                projectionMatrix=camera.projection_matrix(),
                renderer=pybullet.ER_TINY_RENDERER,
                shadow=0,
                lightDirection=LIGHT_DIRECTION,
                lightAmbientCoeff=LIGHT_AMBIENT,
                lightDiffuseCoeff=LIGHT_DIFFUSE,
                lightSpecularCoeff=LIGHT_SPECULAR,
                flags=pybullet.ER_NO_SEGMENTATION_MASK,
            )
        finally:
            if hide_human:
                self.set_human_pose(*self._human_pose)
        image = np.ascontiguousarray(np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3])
        if camera.supersample > 1:  # box-average s×s blocks: what CameraSpec.intrinsics assumes
            image = cv2.resize(image, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
        return image

    def _camera_inside_human(self, camera: CameraSpec) -> bool:
        hx, hy, _ = self._human_pose
        cx, cy, cz = camera.position
        return math.hypot(cx - hx, cy - hy) < HUMAN_HIDE_RADIUS and cz < HUMAN_HEIGHT + 0.1

    # ------------------------------------------------------------------ life

    def close(self) -> None:
        """Disconnect the pybullet client (idempotent)."""
        if self._pb is not None:
            try:
                self._pb.disconnect()
            except pybullet.error:
                pass
            self._pb = None

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
