"""``arroch site check|show|generate|schema``: validate, draw and generate site files, and print their JSON Schema."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from protocol.site.errors import SiteError
from protocol.site.load import load_site
from protocol.site.model import Site


def _ranges(numbers: list[int]) -> str:
    """``0-5, 9, 11-12``: tag ids, compactly."""
    parts: list[str] = []
    for n in sorted(numbers):
        if parts and n == int(parts[-1].split("-")[-1]) + 1:
            parts[-1] = f"{parts[-1].split('-')[0]}-{n}"
        else:
            parts.append(str(n))
    return ", ".join(parts)


def summary(site: Site) -> str:
    """A few lines saying what a site holds."""
    doors = ", ".join(f"{d.id}{' (human-operated)' if d.human_operated else ''}" for d in site.doors.values()) or "none"
    passages = ", ".join(site.passages) or "none"
    x0, y0, x1, y1 = site.bounds
    by_robot = {rid: [o.id for o in site.objects.values() if o.robot == rid] for rid in site.robots}
    lines = [
        f"site {site.name} ({site.source}): {x1 - x0:g} m x {y1 - y0:g} m",
        f"  rooms ({len(site.rooms)}): {', '.join(site.rooms)}",
        f"  doors ({len(site.doors)}): {doors}",
        f"  passages ({len(site.passages)}): {passages}",
        f"  landmarks ({len(site.landmarks)}): tags {_ranges([lm.tag for lm in site.landmarks]) or 'none'}",
        f"  robots ({len(site.robots)}): " + ", ".join(f"{r.id} in {r.room}" for r in site.robots.values()),
        f"  objects ({len(site.objects)}): "
        + "; ".join(f"{rid}: {', '.join(objs) or '-'}" for rid, objs in by_robot.items()),
        f"  human: in {site.human.room} at ({site.human.position[0]:g}, {site.human.position[1]:g})",
        f"  walls: {len(site.walls)} segments, {site.params.wall_thickness:g} m thick, {site.params.wall_height:g} m "
        "high",
    ]
    return "\n".join(lines)


SITE_FILE_HELP = "site file (TOML); default: the packaged 'office' site, as for every other command"


def _load_or_report(path: str | None) -> Site | None:
    try:
        return load_site(path)
    except SiteError as exc:
        print(f"site refused: {exc}", file=sys.stderr)
        return None


def cmd_check(args: argparse.Namespace) -> int:
    site = _load_or_report(args.file)
    if site is None:
        return 2  # bad input, as for every command (docs/architecture.md, "Exit codes")
    print(summary(site))
    print("ok")
    return 0


MIN_DPI, MAX_DPI = 10, 600  # a site drawing is about 16 x 12 inches: 600 dpi is already 70 megapixels


def cmd_show(args: argparse.Namespace) -> int:
    if not MIN_DPI <= args.dpi <= MAX_DPI:
        print(f"--dpi must be within [{MIN_DPI}, {MAX_DPI}], got {args.dpi}", file=sys.stderr)
        return 2
    site = _load_or_report(args.file)
    if site is None:
        return 2
    from .render import render_site  # matplotlib loads only when drawing

    try:
        out = render_site(site, args.png, dpi=args.dpi)
    except OSError as exc:
        print(f"cannot write {args.png}: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {out} (site {site.name})")
    return 0


def cmd_generate(args: argparse.Namespace) -> int:
    from .generate import generate_site

    try:
        text = generate_site(args.robots, args.objects, args.seed)
    except (ValueError, TypeError) as exc:
        print(f"cannot generate: {exc}", file=sys.stderr)
        return 2
    if args.out in (None, "-"):
        sys.stdout.write(text)
        return 0
    try:
        Path(args.out).write_text(text, encoding="utf-8")
    except OSError as exc:
        print(f"cannot write {args.out}: {exc.strerror}", file=sys.stderr)
        return 1
    print(f"wrote {args.out}: {args.robots} robots x {args.objects} objects, seed {args.seed}", file=sys.stderr)
    return 0


def cmd_schema(args: argparse.Namespace) -> int:
    import json

    from protocol.site.fileformat import site_schema

    print(json.dumps(site_schema(), indent=2))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "site", help="check, draw or generate site files, or print their JSON Schema", description=__doc__
    )
    sub = parser.add_subparsers(dest="site_command", metavar="SUBCOMMAND", required=True)

    check = sub.add_parser(
        "check", help="validate a site file and print a summary (exit 2 with the reason if it is refused)"
    )
    check.add_argument("file", nargs="?", help=SITE_FILE_HELP)
    check.set_defaults(func=cmd_check)

    show = sub.add_parser("show", help="draw a site top-down into a PNG")
    show.add_argument("file", nargs="?", help=SITE_FILE_HELP)
    show.add_argument("--png", required=True, metavar="OUT", help="PNG file to write")
    show.add_argument("--dpi", type=int, default=150, help=f"resolution, {MIN_DPI} to {MAX_DPI} (default 150)")
    show.set_defaults(func=cmd_show)

    gen = sub.add_parser("generate", help="write a generated office-like site (deterministic for a seed)")
    gen.add_argument("--robots", type=int, required=True, metavar="N", help="number of robots")
    gen.add_argument("--objects", type=int, default=3, metavar="K", help="objects per robot (default 3)")
    gen.add_argument("--seed", type=int, default=0, metavar="S", help="random seed (default 0)")
    gen.add_argument("--out", metavar="FILE", help="file to write (default: standard output)")
    gen.set_defaults(func=cmd_generate)

    schema = sub.add_parser(
        "schema", help="print the JSON Schema of site files (tables, keys, types, ranges) for editors and tools"
    )
    schema.set_defaults(func=cmd_schema)
