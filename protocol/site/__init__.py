"""Site files: loading and validation, derived geometry, occupancy grid (tools: :mod:`runtime.site`).

A site is a TOML file describing the building (rooms, doors, passages, wall landmarks), the
robots, the objects to deliver and the human (DESIGN §2; the "Site model" section of
docs/services/protocol.md is the API). Every service loads the same file with :func:`load_site`, so
every service agrees on geometry.
"""

from .errors import SiteError
from .grid import OccupancyGrid
from .load import default_site_path, load_site, loads_site
from .model import DoorLeaf, HumanSpec, Landmark, ObjectSpec, Opening, Params, RobotSpec, Room, Site, WallSegment

__all__ = [
    "load_site",
    "loads_site",
    "SiteError",
    "Site",
    "Params",
    "Room",
    "Opening",
    "Landmark",
    "RobotSpec",
    "ObjectSpec",
    "HumanSpec",
    "WallSegment",
    "DoorLeaf",
    "OccupancyGrid",
    "default_site_path",
]
