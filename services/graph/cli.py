"""``arroch graph``: print or draw the service graph declared in :mod:`protocol.graph`.

Text (the default) lists each service's publications, subscriptions, queryables and queries with
their message types; ``--format json|dot|markdown`` writes it for tools, Graphviz or the docs
(docs/graph.md is ``arroch graph --format markdown --out docs/graph.md``); ``--out FILE.png`` or
``FILE.svg`` draws it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from protocol.graph import BY_NAME, SERVICES


def run_graph(args: argparse.Namespace) -> int:
    from .draw import draw, is_picture
    from .formats import WRITERS

    unknown = [name for name in args.service or () if name not in BY_NAME]
    if unknown:
        print(f"arroch graph: no service {', '.join(unknown)} (services: {', '.join(BY_NAME)})", file=sys.stderr)
        return 2
    services = [BY_NAME[name] for name in args.service] if args.service else list(SERVICES)
    out = Path(args.out) if args.out else None
    picture = out is not None and is_picture(out)
    if picture and args.format is not None:
        print(f"arroch graph: --format {args.format} does not apply to a picture ({out.name})", file=sys.stderr)
        return 2
    if out is None:
        sys.stdout.write(WRITERS[args.format or "text"](services))
        return 0
    try:
        if picture:
            draw(services, out)
        else:
            out.write_text(WRITERS[args.format or "text"](services), encoding="utf-8")
    except OSError as exc:
        print(f"arroch graph: cannot write {out}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    print(f"wrote {out}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "graph",
        help="the service graph: who publishes, subscribes, serves and asks which key, with which type",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--format", choices=("text", "json", "dot", "markdown"), help="what to write (default text)")
    parser.add_argument(
        "--out", metavar="FILE", help="write there instead of printing; FILE.png or FILE.svg draws the graph"
    )
    parser.add_argument(
        "--service",
        action="append",
        metavar="NAME",
        help=f"only this service (repeatable; {', '.join(BY_NAME)})",
    )
    parser.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    parser.set_defaults(func=run_graph)
