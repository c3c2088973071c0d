"""Generated office-like sites for experiments with any number of robots and objects.

``generate_site(robots, objects_per_robot=3, seed=0, **options)`` returns the TOML text of a
valid site (``arroch site generate`` writes it to a file). The layout:

- an east-west corridor (``corridor_width``, default 2 m) with a row of rooms on each side,
  each ``room_depth`` (4 m) deep. There are ``robots + extra_rooms`` rooms (``extra_rooms``
  defaults to 2, at least 4 rooms in all), half on the north side (``north_1``, ``north_2``, ...
  from west to east) and the rest on the south side (``south_1``, ...), at least ``room_width``
  (4 m) wide each, so the building grows with the team;
- a ``storage`` room (``storage_width``, 5 m) in the middle of the south row, reached only
  through the human-operated door ``d_storage`` (``storage_door_width``, 0.8 m) at its
  north-west corner; the human stands inside, near its south-east corner;
- every other room opens on the corridor through an ordinary door ``d_<room>``
  (``door_width``, 0.9 m) or, with probability ``passage_probability`` (0.4), a passage
  (``passage_width``, 1.2 m); neighbouring rooms on the same side are joined by a passage
  with probability ``side_passage_probability`` (0.3);
- landmarks (36h11, ``tag_size`` 0.16 m) on the storage walls, placed like the default
  site's (:func:`runtime.site.tags.place_room_tags`: a tablet anywhere in the storage room
  sees at least two);
- the robots ``r0``, ``r1``, ... evenly spaced along the corridor, facing east;
- ``objects_per_robot`` objects per robot (``o0``, ``o1``, ...; robot ``r<i>`` owns
  ``o<i*K>``..``o<i*K+K-1>``), each in a random room other than the corridor and storage, at
  least 0.6 m from walls and door swings and 1 m from other objects, all delivered to ``storage``.

Any :class:`~protocol.site.model.Params` field (``robot_speed``, ``load_time``, ...) may be given
as an option and is written to ``[params]``; ``name`` sets the site name (default
``gen_<robots>x<K>_s<seed>``). The same arguments always give the same text. The result is
loaded and validated before it is returned, so a generated site is always valid.
"""

from __future__ import annotations

import dataclasses
import math
import random
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

from protocol.site.geometry import box_distance, in_swing
from protocol.site.load import loads_site
from protocol.site.model import Params, Site

from .tags import place_room_tags
from .tomlw import dump_site


@dataclass(frozen=True)
class Layout:
    """The generator's layout options (all in metres or probabilities)."""

    room_width: float = 4.0
    room_depth: float = 4.0
    corridor_width: float = 2.0
    storage_width: float = 5.0
    door_width: float = 0.9
    storage_door_width: float = 0.8
    passage_width: float = 1.2
    passage_probability: float = 0.4
    side_passage_probability: float = 0.3
    extra_rooms: int = 2
    tag_size: float = 0.16
    name: str | None = None


OBJECT_CLEARANCE = 0.6  # from walls and door swings
OBJECT_SPACING = 1.0  # between objects, so robots loading neighbours do not collide
PLACEMENT_TRIES = 200


def _split_options(options: dict[str, Any]) -> tuple[Layout, dict[str, Any]]:
    layout_fields = {f.name for f in dataclasses.fields(Layout)}
    param_fields = {f.name for f in dataclasses.fields(Params)}
    layout_opts, params = {}, {}
    for key, value in options.items():
        if key in layout_fields:
            layout_opts[key] = value
        elif key in param_fields:
            params[key] = value
        else:
            raise TypeError(
                f"generate_site: unknown option {key!r} (layout: {', '.join(sorted(layout_fields))}; params: "
                f"{', '.join(sorted(param_fields))})"
            )
    return Layout(**layout_opts), params


def _r(v: float) -> float:
    """Round a coordinate to the millimetre, so the text is short and stable."""
    return round(v, 3) + 0.0  # + 0.0 turns -0.0 into 0.0


def _structure(n_robots: int, layout: Layout, params: dict[str, Any], name: str, rng: random.Random) -> dict[str, Any]:
    """Rooms, openings, robots and the human (no landmarks or objects yet)."""
    n_rooms = max(4, n_robots + layout.extra_rooms)
    n_north = math.ceil(n_rooms / 2)
    n_south = n_rooms - n_north
    length = max(n_north * layout.room_width, n_south * layout.room_width + layout.storage_width)
    y_cs, y_cn = layout.room_depth, layout.room_depth + layout.corridor_width  # corridor's south and north edges
    rooms = [{"id": "corridor", "rect": [0.0, _r(y_cs), _r(length), _r(y_cn)]}]
    north_w = length / n_north
    for i in range(n_north):
        rooms.append(
            {
                "id": f"north_{i + 1}",
                "rect": [_r(i * north_w), _r(y_cn), _r((i + 1) * north_w), _r(y_cn + layout.room_depth)],
            }
        )
    south_w = (length - layout.storage_width) / n_south
    storage_at = n_south // 2  # storage sits in the middle of the south row
    x = 0.0
    south_ids = []
    for i in range(n_south + 1):
        if i == storage_at:
            rooms.append({"id": "storage", "rect": [_r(x), 0.0, _r(x + layout.storage_width), _r(y_cs)]})
            x += layout.storage_width
        else:
            rid = f"south_{len(south_ids) + 1}"
            south_ids.append(rid)
            rooms.append({"id": rid, "rect": [_r(x), 0.0, _r(x + south_w), _r(y_cs)]})
            x += south_w
    half_t = params.get("wall_thickness", Params.wall_thickness) / 2.0
    storage = next(r for r in rooms if r["id"] == "storage")
    sx0 = storage["rect"][0]
    doors = [
        {
            "id": "d_storage",
            "rooms": ["corridor", "storage"],
            "center": [_r(sx0 + half_t + layout.storage_door_width / 2.0), _r(y_cs)],
            "width": layout.storage_door_width,
            "human_operated": True,
        }
    ]
    passages = []
    for room in rooms[1:]:
        if room["id"] == "storage":
            continue
        x0, _, x1, _ = room["rect"]
        wall_y = y_cn if room["id"].startswith("north") else y_cs
        if rng.random() < layout.passage_probability:
            width, entry = layout.passage_width, {"rooms": ["corridor", room["id"]]}
            passages.append(entry)
        else:
            width, entry = layout.door_width, {"id": f"d_{room['id']}", "rooms": ["corridor", room["id"]]}
            doors.append(entry)
        margin = width / 2.0 + 0.3
        entry["center"] = [_r(rng.uniform(x0 + margin, x1 - margin)), _r(wall_y)]
        entry["width"] = width
    for side in ("north", "south"):
        row = [r for r in rooms if r["id"].startswith(side)]
        for west, east in pairwise(row):
            if west["rect"][2] != east["rect"][0] or rng.random() >= layout.side_passage_probability:
                continue  # storage between them, or no passage this time
            y0, y1 = west["rect"][1], west["rect"][3]
            near_corridor = 1.6  # keep clear of the corridor doors' leaves
            lo, hi = (y0 + 0.8, y1 - near_corridor) if side == "south" else (y0 + near_corridor, y1 - 0.8)
            y = _r(rng.uniform(lo, hi)) if hi > lo else _r((y0 + y1) / 2.0)
            passages.append(
                {"rooms": [west["id"], east["id"]], "center": [_r(west["rect"][2]), y], "width": layout.passage_width}
            )
    robots = [
        {"id": f"r{i}", "start": [_r((i + 0.5) * length / n_robots), _r((y_cs + y_cn) / 2.0), 0.0]}
        for i in range(n_robots)
    ]
    sx1 = storage["rect"][2]
    human = {"room": "storage", "position": [_r(sx1 - 1.2), 1.2]}
    return {
        "site": {"name": name},
        "params": params,
        "rooms": rooms,
        "doors": doors,
        "passages": passages,
        "landmarks": [],
        "robots": robots,
        "objects": [],
        "human": human,
    }


def _place_objects(site: Site, n_robots: int, per_robot: int, rng: random.Random) -> list[dict[str, Any]]:
    candidates = [r for r in site.rooms.values() if r.id not in ("corridor", "storage")]
    placed: list[tuple[float, float]] = []
    objects = []
    for i in range(n_robots * per_robot):
        for _ in range(PLACEMENT_TRIES):
            room = rng.choice(candidates)
            x0, y0, x1, y1 = room.rect
            x, y = (
                _r(rng.uniform(x0 + OBJECT_CLEARANCE, x1 - OBJECT_CLEARANCE)),
                _r(rng.uniform(y0 + OBJECT_CLEARANCE, y1 - OBJECT_CLEARANCE)),
            )
            if min(box_distance(w.box, x, y) for w in site.walls) < OBJECT_CLEARANCE:
                continue
            if any(in_swing(leaf, x, y, OBJECT_CLEARANCE) for leaf in site.door_leaves.values()):
                continue
            if any(math.dist((x, y), p) < OBJECT_SPACING for p in placed):
                continue
            break
        else:
            raise ValueError(
                f"generate_site: no free place for object o{i} after {PLACEMENT_TRIES} tries (rooms too small for "
                f"{n_robots * per_robot} objects)"
            )
        placed.append((x, y))
        objects.append({"id": f"o{i}", "position": [x, y], "deliver_to": "storage", "robot": f"r{i // per_robot}"})
    return objects


# Bounds that keep generation to seconds (it grows about with the square of the robots: 500 take ~5 s).
MAX_ROBOTS = 500
MAX_OBJECTS_PER_ROBOT = 100


def generate_site(robots: int, objects_per_robot: int = 3, seed: int = 0, **options: Any) -> str:
    """TOML text of a valid office-like site with ``robots`` robots and ``objects_per_robot`` objects each.

    Deterministic for the same arguments; see the module docstring for the layout and options.
    Raises ``ValueError``/``TypeError`` for impossible or unknown options.
    """
    for label, value, low, high in (
        ("robots", robots, 1, MAX_ROBOTS),
        ("objects_per_robot", objects_per_robot, 0, MAX_OBJECTS_PER_ROBOT),
    ):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"generate_site: {label} must be an integer >= {low}, got {value!r}")
        if value > high:
            raise ValueError(f"generate_site: {label} must be at most {high}, got {value!r}")
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ValueError(f"generate_site: seed must be an integer, got {seed!r}")
    layout, params = _split_options(options)
    name = layout.name or f"gen_{robots}x{objects_per_robot}_s{seed}"
    rng = random.Random(seed)
    doc = _structure(robots, layout, params, name, rng)
    bare = loads_site(dump_site(doc), f"{name}.toml")  # validates the structure, gives its geometry
    storage = bare.rooms["storage"]
    doc["landmarks"] = place_room_tags(
        storage,
        [o for o in bare.openings.values() if "storage" in o.rooms],
        [leaf for leaf in bare.door_leaves.values() if leaf.swing_into == "storage"],
        bare.params.wall_thickness,
        size=layout.tag_size,
    )
    doc["objects"] = _place_objects(bare, robots, objects_per_robot, rng)
    header = (
        f"Generated by runtime.site.generate.generate_site(robots={robots}, "
        f"objects_per_robot={objects_per_robot}, seed={seed}"
        + "".join(f", {k}={v!r}" for k, v in sorted(options.items()))
        + ").\nRegenerate rather than edit: `arroch site generate`."
    )
    text = dump_site({k: v for k, v in doc.items() if v or k == "site"}, header=header)
    loads_site(text, f"{name}.toml")  # a generated site is always valid; this refuses a generator bug loudly
    return text
