"""The service graph as a picture (PNG or SVG, matplotlib: no Graphviz needed).

A layered drawing of the data flow: the services that write a key (publish or serve it) on the left,
the ARROCH keys in the middle, the services that read it (subscribe or ask) on the right, so every
edge runs left to right. A service therefore appears on both sides. Keys are ordered by the mean
row of their writers, readers by the mean row of the keys they read, which keeps most edges short.
Served and asked keys are drawn dashed; keys used only under a condition (an option), faded. ROS 2
topics are left out (see ``arroch graph`` as text).
"""

from __future__ import annotations

import colorsys
import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from protocol.graph import ServiceNode

WRITING = ("pub", "serve")
ROW = 0.42  # inches per row of the tallest column
X_WRITERS, X_KEYS, X_READERS = 0.0, 1.0, 2.0
DPI = 110
PNG_COLOURS = 128  # enough for the services' colours, their faded variants and anti-aliasing


def _colour(index: int) -> tuple[float, float, float]:
    """A distinct colour per service (hues a golden ratio apart), dark enough for thin lines."""
    return colorsys.hsv_to_rgb((0.05 + index * 0.618034) % 1.0, 0.75, 0.8)


def _rows(names: Sequence[str]) -> dict[str, float]:
    """Evenly spaced rows, top to bottom, centred on 0."""
    middle = (len(names) - 1) / 2
    return {name: middle - i for i, name in enumerate(names)}


def _by_mean(items: dict[str, list[float]], fallback: dict[str, int]) -> list[str]:
    """Items sorted by the mean of their neighbours' rows (highest first), ties in ``fallback`` order."""
    return sorted(items, key=lambda item: (-sum(items[item]) / max(len(items[item]), 1), fallback[item]))


def draw(services: Sequence[ServiceNode], out: Path) -> None:
    """Draw ``services`` to ``out`` (its suffix, .png or .svg, chooses the format)."""
    import matplotlib

    matplotlib.use("Agg")  # files only, whatever display there is
    import matplotlib.pyplot as plt

    edges = [(s, e) for s in services for e in s.endpoints if not e.is_ros2]
    writers = [s.name for s in services if any(e.direction in WRITING for e in s.endpoints if not e.is_ros2)]
    readers = [s.name for s in services if any(e.direction not in WRITING for e in s.endpoints if not e.is_ros2)]
    order = {s.name: i for i, s in enumerate(services)}
    writer_rows = _rows(writers)
    key_neighbours: dict[str, list[float]] = {}
    for service, e in edges:
        key_neighbours.setdefault(e.key, [])
        if e.direction in WRITING:
            key_neighbours[e.key].append(writer_rows[service.name])
    first_seen = {key: i for i, key in enumerate(key_neighbours)}
    key_rows = _rows(_by_mean(key_neighbours, first_seen))
    reader_neighbours: dict[str, list[float]] = {name: [] for name in readers}
    for service, e in edges:
        if e.direction not in WRITING:
            reader_neighbours[service.name].append(key_rows[e.key])
    reader_rows = _rows(_by_mean(reader_neighbours, order))

    tallest = max(len(writers), len(key_rows), len(readers))
    fig, ax = plt.subplots(figsize=(13, ROW * tallest + 1.2))
    scale = tallest / max(len(writers), 1), 1.0, tallest / max(len(readers), 1)
    y_writer = {name: row * scale[0] for name, row in writer_rows.items()}
    y_reader = {name: row * scale[2] for name, row in reader_rows.items()}

    for service, e in edges:
        colour = _colour(order[service.name])
        x0, y0, x1, y1 = (
            (X_WRITERS, y_writer[service.name], X_KEYS, key_rows[e.key])
            if e.direction in WRITING
            else (X_KEYS, key_rows[e.key], X_READERS, y_reader[service.name])
        )
        ax.annotate(
            "",
            xy=(x1 - 0.12 if x1 == X_KEYS else x1 - 0.1, y1),
            xytext=(x0 + 0.1 if x0 == X_WRITERS else x0 + 0.12, y0),
            arrowprops={
                "arrowstyle": "-|>",
                "color": colour,
                "alpha": 0.35 if e.when else 0.85,
                "linestyle": "--" if e.direction in ("serve", "query") else "-",
                "linewidth": 1.0,
                "shrinkA": 0,
                "shrinkB": 0,
                "mutation_scale": 8,
            },
        )
    box = {"boxstyle": "round,pad=0.3", "linewidth": 1.2}
    for names, x, ys in ((writers, X_WRITERS, y_writer), (readers, X_READERS, y_reader)):
        for name in names:
            colour = _colour(order[name])
            ax.text(x, ys[name], name, ha="center", va="center", fontsize=9, bbox={**box, "fc": "white", "ec": colour})
    for key, y in key_rows.items():
        payloads = sorted({e.payload_name for _, e in edges if e.key == key})
        label = f"{key}\n{', '.join(payloads)}"
        ax.text(X_KEYS, y, label, ha="center", va="center", fontsize=7, bbox={**box, "fc": "#f2f2f2", "ec": "#999999"})
    top = (tallest - 1) / 2 + 0.9
    for x, title in (
        (X_WRITERS, "publishes / serves"),
        (X_KEYS, "key (below arroch/<namespace>/)"),
        (X_READERS, "subscribes / asks"),
    ):
        ax.text(x, top, title, ha="center", va="bottom", fontsize=10, weight="bold")
    ax.set_xlim(-0.25, 2.25)
    ax.set_ylim(-top, top + 0.5)
    ax.axis("off")
    fig.tight_layout()
    if out.suffix.lower() == ".svg":
        # No creation date or software version: the file changes only with the graph.
        fig.savefig(out, metadata={"Date": None, "Creator": None})
    else:
        _save_small_png(fig, out)
    plt.close(fig)


def _save_small_png(fig: Any, out: Path) -> None:
    """A palette PNG: the drawing has few colours, and a quarter of the bytes of matplotlib's RGBA
    PNG is what a picture kept in the repository should weigh. Pillow writes no date either."""
    from PIL import Image

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI)
    buffer.seek(0)
    with Image.open(buffer) as image:
        image.convert("RGB").quantize(colors=PNG_COLOURS).save(out, format="PNG", optimize=True)


def is_picture(path: Path) -> bool:
    return path.suffix.lower() in (".png", ".svg")
