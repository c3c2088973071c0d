"""A top-down picture of a site (PNG): rooms, walls, doors by kind, passages, landmarks, robots,
objects and the human, with a legend and a scale bar."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never needs a display

import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Arc, Circle, Patch, Rectangle  # noqa: E402

from protocol.site.model import Opening, Site  # noqa: E402

WALL = "#3b3b3b"
HUMAN_DOOR = "#d62728"
ROBOT_DOOR = "#1f77b4"
PASSAGE = "#2ca02c"
LANDMARK = "#7b3fb5"
ROOM = "#f4f1ea"
HUMAN_ROOM = "#fde8d7"
HUMAN = "#c2185b"
ROBOT_COLOURS = plt.get_cmap("tab10").colors


def _robot_colour(index: int) -> tuple:
    return ROBOT_COLOURS[index % len(ROBOT_COLOURS)]


def _opening_label_pos(o: Opening, site: Site, away: float) -> tuple[float, float, str, str]:
    """Where to write an opening's id: just off the wall, on the side its leaf does not swing into."""
    leaf = site.door_leaves.get(o.id)
    side = o.other(leaf.swing_into) if leaf else o.rooms[0]
    x, y = o.beside(side, away)
    if o.axis == "x":
        return x, y, "center", "top" if y < o.center[1] else "bottom"
    # Written upwards along the wall: the text's bottom faces +x.
    return x, y, "center", "bottom" if x < o.center[0] else "top"


def _draw_door(ax, o: Opening, site: Site) -> None:  # noqa: ANN001
    leaf = site.door_leaves[o.id]
    colour = HUMAN_DOOR if o.human_operated else ROBOT_DOOR
    (hx, hy), (tx, ty) = leaf.hinge, leaf.tip(open=False)
    ax.plot([hx, tx], [hy, ty], color=colour, lw=3.2, solid_capstyle="butt", zorder=5)
    ox, oy = leaf.tip(open=True)
    ax.plot([hx, ox], [hy, oy], color=colour, lw=0.8, ls=(0, (2, 2)), zorder=4)
    start, end = sorted((math.degrees(leaf.closed_yaw), math.degrees(leaf.open_yaw)))
    if end - start > 180:  # take the 90° way round
        start, end = end, start + 360
    ax.add_patch(
        Arc(
            (hx, hy),
            2 * leaf.length,
            2 * leaf.length,
            theta1=start,
            theta2=end,
            color=colour,
            lw=0.8,
            ls="--",
            zorder=4,
        )
    )


def _draw_passage(ax, o: Opening) -> None:  # noqa: ANN001
    (x0, y0), (x1, y1) = o.endpoints
    ax.plot([x0, x1], [y0, y1], color=PASSAGE, lw=2.0, ls=(0, (1.5, 1.2)), zorder=5)


def _scale_bar(ax, x: float, y: float, length: float) -> None:  # noqa: ANN001
    ax.plot([x, x + length], [y, y], color="black", lw=2.5, solid_capstyle="butt", zorder=8)
    for end in (x, x + length):
        ax.plot([end, end], [y - 0.12, y + 0.12], color="black", lw=1.2, zorder=8)
    ax.text(x + length / 2, y + 0.18, f"{length:g} m", ha="center", va="bottom", fontsize=8, zorder=8)


def render_site(site: Site, out: str | Path, dpi: int = 150) -> Path:
    """Draw ``site`` top-down into the PNG file ``out`` and return its path."""
    bx0, by0, bx1, by1 = site.bounds
    width, height = bx1 - bx0, by1 - by0
    scale = min(0.75, 16.0 / width)  # inches per metre; wide sites shrink to stay readable
    fig, ax = plt.subplots(figsize=(max(width * scale, 7.0) + 0.8, height * scale + 2.2))
    text_size = 7 if scale >= 0.6 else 5.5

    for room in site.rooms.values():
        x0, y0, x1, y1 = room.rect
        ax.add_patch(
            Rectangle(
                (x0, y0),
                x1 - x0,
                y1 - y0,
                facecolor=HUMAN_ROOM if room.id == site.human.room else ROOM,
                edgecolor="none",
                zorder=0,
            )
        )
        ax.text(
            x0 + 0.2,
            y1 - 0.2,
            room.id,
            ha="left",
            va="top",
            fontsize=text_size + 1.5,
            color="#6d6a63",
            weight="bold",
            zorder=1,
        )
    for wall in site.walls:
        x0, y0, x1, y1 = wall.box
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor=WALL, edgecolor="none", zorder=3))
    for o in site.openings.values():
        _draw_door(ax, o, site) if o.kind == "door" else _draw_passage(ax, o)
        x, y, ha, va = _opening_label_pos(o, site, 0.12)
        colour = PASSAGE if o.kind == "passage" else (HUMAN_DOOR if o.human_operated else ROBOT_DOOR)
        ax.text(
            x,
            y,
            o.id,
            ha=ha,
            va=va,
            fontsize=text_size - 0.5,
            color=colour,
            zorder=6,
            rotation=0 if o.axis == "x" else 90,
            rotation_mode="anchor",
        )

    for lm in site.landmarks:
        corners = lm.corners(printed=True)
        (x0, y0), (x1, y1) = corners[0][:2], corners[1][:2]
        ax.plot([x0, x1], [y0, y1], color=LANDMARK, lw=3.0, solid_capstyle="butt", zorder=6)
        nx, ny = math.cos(lm.yaw), math.sin(lm.yaw)
        px, py = lm.position[0], lm.position[1]
        ax.annotate(
            "",
            xy=(px + 0.28 * nx, py + 0.28 * ny),
            xytext=(px, py),
            zorder=6,
            arrowprops={"arrowstyle": "-|>", "color": LANDMARK, "lw": 0.7, "mutation_scale": 5},
        )
        ax.text(
            px + 0.42 * nx,
            py + 0.42 * ny,
            str(lm.tag),
            ha="center",
            va="center",
            fontsize=text_size - 1.5,
            color=LANDMARK,
            zorder=6,
        )

    robot_index = {rid: i for i, rid in enumerate(site.robots)}
    for obj in site.objects.values():
        colour = _robot_colour(robot_index[obj.robot])
        x, y = obj.position
        ax.add_patch(Rectangle((x - 0.15, y - 0.15), 0.3, 0.3, facecolor=colour, edgecolor="black", lw=0.6, zorder=7))
        # Write towards the room's middle, so the label stays inside the room.
        left = x > site.rooms[obj.room].center[0]
        ax.text(
            x - 0.25 if left else x + 0.25,
            y,
            f"{obj.id} ({obj.robot}) \u2192 {obj.deliver_to}",
            ha="right" if left else "left",
            va="center",
            fontsize=text_size - 0.5,
            zorder=7,
        )
    radius = site.params.robot_radius
    for rid, robot in site.robots.items():
        colour = _robot_colour(robot_index[rid])
        x, y, theta = robot.start
        ax.add_patch(Circle((x, y), radius, facecolor=colour, edgecolor="black", lw=0.8, zorder=7))
        ax.plot(
            [x, x + 1.6 * radius * math.cos(theta)],
            [y, y + 1.6 * radius * math.sin(theta)],
            color="black",
            lw=1.4,
            zorder=8,
        )
        # The id goes behind the robot (opposite its heading), so the heading line never hides it.
        lx, ly = x - (radius + 0.2) * math.cos(theta), y - (radius + 0.2) * math.sin(theta)
        ax.text(lx, ly, rid, ha="center", va="center", fontsize=text_size + 0.5, weight="bold", zorder=8)
    hx, hy = site.human.position
    ax.plot([hx], [hy], marker="*", markersize=16, color=HUMAN, markeredgecolor="black", zorder=8)
    ax.text(
        hx, hy - 0.3, "human", ha="center", va="top", fontsize=text_size + 0.5, color=HUMAN, weight="bold", zorder=8
    )

    _scale_bar(ax, bx0 + 0.3, by0 - 0.75, 5.0 if width >= 12 else 1.0)
    ax.set_xlim(bx0 - 0.5, bx1 + 0.5)
    ax.set_ylim(by0 - 1.0, by1 + 0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, east)", fontsize=8)
    ax.set_ylabel("y (m, north)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(True, color="#dddddd", lw=0.4, zorder=-1)
    ax.set_axisbelow(True)
    ax.set_title(
        f"site {site.name}: {len(site.rooms)} rooms, {len(site.doors)} doors, {len(site.passages)} passages, "
        f"{len(site.landmarks)} landmarks, {len(site.robots)} robots, {len(site.objects)} objects",
        fontsize=10,
    )
    handles = [
        Patch(facecolor=WALL, label=f"wall ({site.params.wall_thickness:g} m, {site.params.wall_height:g} m high)"),
        Line2D([], [], color=HUMAN_DOOR, lw=3, label="human-operated door (leaf, swing)"),
        Line2D([], [], color=ROBOT_DOOR, lw=3, label="door robots open (leaf, swing)"),
        Line2D([], [], color=PASSAGE, lw=2, ls=(0, (1.5, 1.2)), label="passage (no door)"),
        Line2D([], [], color=LANDMARK, lw=3, marker=">", markersize=4, label="landmark: tag id, facing"),
        Line2D(
            [],
            [],
            marker="o",
            color="none",
            markerfacecolor=_robot_colour(0),
            markeredgecolor="black",
            markersize=9,
            label="robot, heading",
        ),
        Line2D(
            [],
            [],
            marker="s",
            color="none",
            markerfacecolor=_robot_colour(0),
            markeredgecolor="black",
            markersize=7,
            label="object (owner) \u2192 destination",
        ),
        Line2D(
            [],
            [],
            marker="*",
            color="none",
            markerfacecolor=HUMAN,
            markeredgecolor="black",
            markersize=12,
            label="human",
        ),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    path = Path(out)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
