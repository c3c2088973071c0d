"""Printable landmark tags: one page per landmark, the tag at its true size, where it goes, which way is up.

``arroch tags sheet --site FILE --out tags.pdf`` writes a multi-page PDF; ``--out DIR/`` or
``--out NAME.png`` writes one PNG per page (``NAME_<tag>.png``) at ``--dpi``. Each page shows the
official tag36h11 image of the landmark (:func:`runtime.apriltag.tag_image`, the same pixels the
simulator renders) with its one-module white border, scaled so the black square measures the
landmark's ``size``; an "UP" arrow; a 100 mm scale bar to check the printer did not rescale; and the
landmark's place: room, wall, centre position and height, facing direction.

Print at 100 % ("actual size"); the white border is part of the tag: cut outside it.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.backends.backend_pdf import PdfPages  # noqa: E402

from runtime.apriltag import quad_edge, tag_image  # noqa: E402

A4 = (8.27, 11.69)  # inches
MARGIN_IN = 0.6
INCH = 0.0254  # metres
COMPASS = ("east (+x)", "north-east", "north (+y)", "north-west", "west (-x)", "south-west", "south (-y)", "south-east")


def facing_name(yaw: float) -> str:
    return COMPASS[int(round((math.degrees(yaw) % 360.0) / 45.0)) % 8]


def placement(site, lm) -> str:  # noqa: ANN001
    """Where a landmark goes, in words: room, wall, centre, height, facing."""
    nx, ny, _ = lm.normal
    x, y, z = lm.position
    room = site.room_at(x + 0.2 * nx, y + 0.2 * ny)
    # The wall a tag hangs on is the one opposite the direction it faces.
    wall = facing_name(lm.yaw + math.pi).split(" ")[0]
    where = f"room '{room.id}', on its {wall} wall" if room is not None else "on a wall"
    return (
        f"{where}, facing {facing_name(lm.yaw)} (yaw {math.degrees(lm.yaw):.0f} deg)\n"
        f"centre of the tag at x = {x:.3f} m, y = {y:.3f} m, height {z:.3f} m above the floor"
    )


def _page(site, lm):  # noqa: ANN001, ANN202
    """One matplotlib figure for a landmark, physically to scale."""
    edge_in = quad_edge(lm.size, 1) / INCH
    page_w = max(A4[0], edge_in + 2 * MARGIN_IN)
    page_h = max(A4[1], edge_in + 5.0)
    fig = plt.figure(figsize=(page_w, page_h))
    left = (page_w - edge_in) / 2.0
    bottom = (page_h - edge_in) / 2.0 - 0.5
    ax = fig.add_axes((left / page_w, bottom / page_h, edge_in / page_w, edge_in / page_h))
    image = tag_image(lm.tag, module_px=1, border_modules=1)
    ax.imshow(image, cmap="gray", vmin=0, vmax=255, interpolation="nearest", aspect="auto")
    ax.set_axis_off()
    # A hairline frame around the printed image (outside the white border) as the cutting line.
    frame = fig.add_axes((left / page_w, bottom / page_h, edge_in / page_w, edge_in / page_h), facecolor="none")
    frame.set_xticks([])
    frame.set_yticks([])
    for spine in frame.spines.values():
        spine.set_linewidth(0.3)
        spine.set_linestyle((0, (4, 4)))
    top = (bottom + edge_in) / page_h
    fig.text(0.5, top + 0.9 / page_h, "UP", ha="center", va="bottom", fontsize=20, weight="bold")
    fig.patches.append(
        matplotlib.patches.FancyArrow(
            0.5,
            top + 0.2 / page_h,
            0.0,
            0.6 / page_h,
            width=0.06 / page_w,
            head_width=0.3 / page_w,
            head_length=0.25 / page_h,
            length_includes_head=True,
            transform=fig.transFigure,
            color="black",
        )
    )
    fig.text(0.5, 1.0 - 0.5 / page_h, f"AprilTag 36h11  id {lm.tag}", ha="center", va="top", fontsize=22, weight="bold")
    fig.text(
        0.5,
        1.0 - 0.95 / page_h,
        f"black square {lm.size * 1000:.0f} mm, with white border {quad_edge(lm.size, 1) * 1000:.0f} mm - print at 100 "
        "% (actual size)",
        ha="center",
        va="top",
        fontsize=10,
    )
    fig.text(0.5, (bottom - 0.35) / page_h, placement(site, lm), ha="center", va="top", fontsize=10, linespacing=1.6)
    # 100 mm scale bar to check the print.
    bar_in = 0.1 / INCH
    y = 0.6 / page_h
    x0 = (page_w - bar_in) / 2.0 / page_w
    fig.add_artist(
        matplotlib.lines.Line2D(
            [x0, x0 + bar_in / page_w], [y, y], transform=fig.transFigure, color="black", linewidth=2
        )
    )
    fig.text(0.5, y + 0.08 / page_h, "100 mm (check the print scale)", ha="center", va="bottom", fontsize=8)
    fig.text(0.5, 0.2 / page_h, f"site '{site.name}'", ha="center", va="bottom", fontsize=7, color="0.4")
    return fig


def write_sheet(site, out: str | Path, dpi: int = 300) -> list[Path]:  # noqa: ANN001
    """Write the sheet for every landmark of ``site``; returns the files written."""
    out = Path(out)
    if not site.landmarks:
        raise ValueError(f"site {site.name!r} has no landmarks")
    landmarks = sorted(site.landmarks, key=lambda lm: lm.tag)
    if out.suffix.lower() == ".pdf":
        out.parent.mkdir(parents=True, exist_ok=True)
        with PdfPages(out) as pdf:
            for lm in landmarks:
                fig = _page(site, lm)
                pdf.savefig(fig)
                plt.close(fig)
        return [out]
    if out.suffix.lower() == ".png":
        folder, stem = out.parent, out.stem
    elif out.suffix == "":
        folder, stem = out, "tag"
    else:
        raise ValueError(f"--out {out}: expected a .pdf file, a .png name or a folder")
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for lm in landmarks:
        fig = _page(site, lm)
        path = folder / f"{stem}_{lm.tag}.png"
        fig.savefig(path, dpi=dpi)
        plt.close(fig)
        written.append(path)
    return written
