"""The service graph written out as text, JSON, Graphviz DOT or Markdown (docs/graph.md)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field

from protocol.graph import DIRECTIONS, FRAMEWORK, Endpoint, ServiceNode

FORMATS = ("text", "json", "dot", "markdown")
KEY_ROOT = "arroch/<namespace>/"
GENERATED_BY = "arroch graph --format markdown --out docs/graph.md"
PICTURE_BY = "arroch graph --out docs/graph.png"
# What each direction is called in the key table: the column a service goes in.
ROLE_COLUMNS = {"pub": "published by", "sub": "subscribed by", "serve": "served by", "query": "asked by"}


@dataclass
class KeyUse:
    """Who uses one key with one payload type, per direction (service names, with their condition)."""

    key: str
    payload: str
    users: dict[str, list[str]] = field(default_factory=lambda: {d: [] for d in DIRECTIONS})


def key_table(services: Sequence[ServiceNode], *, ros2: bool = False) -> list[KeyUse]:
    """One row per (key, payload) of the ARROCH keys (``ros2``: of the ROS 2 topics), sorted by key."""
    rows: dict[tuple[str, str], KeyUse] = {}
    for service in services:
        for endpoint in service.endpoints:
            if endpoint.is_ros2 != ros2:
                continue
            row = rows.setdefault((endpoint.key, endpoint.payload_name), KeyUse(endpoint.key, endpoint.payload_name))
            user = f"{service.name} ({endpoint.when})" if endpoint.when else service.name
            if user not in row.users[endpoint.direction]:
                row.users[endpoint.direction].append(user)
    return [rows[key] for key in sorted(rows)]


def _endpoint_dict(endpoint: Endpoint) -> dict[str, str | bool]:
    return {
        "direction": endpoint.direction,
        "key": endpoint.key,
        "payload": endpoint.payload_name,
        "purpose": endpoint.purpose,
        "when": endpoint.when,
        "ros2": endpoint.is_ros2,
    }


def to_json(services: Sequence[ServiceNode]) -> str:
    body = {
        "key_root": KEY_ROOT,
        "framework": [_endpoint_dict(e) for e in FRAMEWORK],
        "services": [
            {
                "name": s.name,
                "command": s.command,
                "role": s.role,
                "summary": s.summary,
                "endpoints": [_endpoint_dict(e) for e in s.endpoints],
            }
            for s in services
        ],
    }
    return json.dumps(body, indent=2) + "\n"


def to_text(services: Sequence[ServiceNode]) -> str:
    """Per service: what it publishes, subscribes, serves and asks, with types (keys below the root)."""
    lines = [f"Keys below {KEY_ROOT} (topics starting with / are ROS 2 topics)."]
    for service in services:
        role = f"role {service.role}" if service.role else "no access-control role"
        lines += ["", f"{service.name}  ({service.command}; {role})", f"  {service.summary}"]
        key_width = max(len(e.key) for e in service.endpoints)
        type_width = max(len(e.payload_name) for e in service.endpoints)
        for direction in DIRECTIONS:
            for e in service.of(direction):
                when = f"  [{e.when}]" if e.when else ""
                lines.append(
                    f"  {direction:<5}  {e.key:<{key_width}}  {e.payload_name:<{type_width}}  {e.purpose}{when}"
                )
    lines += ["", "Every service also:"]
    lines += [f"  {e.direction:<5}  {e.key}  {e.payload_name}  {e.purpose}" for e in FRAMEWORK]
    return "\n".join(lines) + "\n"


def _dot_id(text: str) -> str:
    return json.dumps(text)  # a double-quoted DOT id, quotes and backslashes escaped


def to_dot(services: Sequence[ServiceNode]) -> str:
    """A Graphviz digraph: services as boxes, keys as ellipses (ROS 2 topics as notes), edges as data
    flows (pub: service -> key, sub: key -> service; serve and query dashed; conditional ones dotted)."""
    lines = ["digraph arroch {", "  rankdir=LR;", '  node [fontname="Helvetica", fontsize=10];']
    for service in services:
        lines.append(f"  {_dot_id('service:' + service.name)} [shape=box, style=bold, label={_dot_id(service.name)}];")
    keys = {(e.key, e.is_ros2) for s in services for e in s.endpoints}
    for key, ros2 in sorted(keys):
        shape = "note" if ros2 else "ellipse"
        lines.append(f"  {_dot_id('key:' + key)} [shape={shape}, label={_dot_id(key)}];")
    for service in services:
        node = _dot_id("service:" + service.name)
        for e in service.endpoints:
            key = _dot_id("key:" + e.key)
            tail, head = (node, key) if e.direction in ("pub", "serve") else (key, node)
            style = "dotted" if e.when else ("dashed" if e.direction in ("serve", "query") else "solid")
            label = e.payload_name if e.direction in ("pub", "sub") else f"{e.direction} {e.payload_name}"
            lines.append(f"  {tail} -> {head} [label={_dot_id(label)}, style={style}];")
    lines.append("}")
    return "\n".join(lines) + "\n"


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _code(key: str) -> str:
    return f"`{key}`"


def to_markdown(services: Sequence[ServiceNode]) -> str:
    """docs/graph.md: the picture, the key table, the ROS 2 topics, and a section per service."""
    lines = [
        f"<!-- Generated by `{GENERATED_BY}` from protocol/graph.py: do not edit, change the declaration."
        " tests/protocol/test_graph.py checks that this file is up to date. -->",
        "",
        "# The service graph",
        "",
        "Which service publishes, subscribes, serves and asks which key, with which message type: the",
        "declaration in `protocol/graph.py`, checked against the running services by",
        "`tests/integration/test_graph_declared.py`. `arroch graph` prints it (`--format text|json|dot|markdown`)",
        f"and draws it (`{PICTURE_BY}`).",
        "",
        f"Keys are below `{KEY_ROOT}`; `*` stands for a robot, door, camera or sender id. A condition in",
        "parentheses is the option or circumstance under which a service uses the key. Message types are",
        "the classes of `protocol/messages.py`.",
        "",
        "![The service graph: writers on the left, keys in the middle, readers on the right](graph.png)",
        "",
        "## Keys",
        "",
        "| key | type | " + " | ".join(ROLE_COLUMNS.values()) + " |",
        "|---|---|" + "---|" * len(ROLE_COLUMNS),
    ]
    for row in key_table(services):
        users = [", ".join(row.users[d]) for d in ROLE_COLUMNS]
        lines.append(f"| {_code(row.key)} | {_cell(row.payload)} | " + " | ".join(_cell(u) for u in users) + " |")
    lines += [
        "",
        "Every service also:",
        "",
        "| direction | key | type | purpose |",
        "|---|---|---|---|",
    ]
    lines += [f"| {e.direction} | {_code(e.key)} | {_cell(e.payload_name)} | {_cell(e.purpose)} |" for e in FRAMEWORK]
    lines += [
        "",
        "## ROS 2 topics",
        "",
        "Reached through rmw_zenoh (`runtime/ros2`); names as configured.",
        "",
        "| topic | type | " + " | ".join(ROLE_COLUMNS.values()) + " |",
        "|---|---|" + "---|" * len(ROLE_COLUMNS),
    ]
    for row in key_table(services, ros2=True):
        users = [", ".join(row.users[d]) for d in ROLE_COLUMNS]
        lines.append(f"| {_code(row.key)} | {_cell(row.payload)} | " + " | ".join(_cell(u) for u in users) + " |")
    lines += ["", "## Services"]
    for service in services:
        role = f"access-control role `{service.role}`" if service.role else "no access-control role"
        lines += [
            "",
            f"### {service.name}",
            "",
            f"`{service.command}` ({role}): {service.summary}.",
            "",
            "| direction | key | type | purpose | when |",
            "|---|---|---|---|---|",
        ]
        for direction in DIRECTIONS:
            for e in service.of(direction):
                fields = (direction, _code(e.key), e.payload_name, e.purpose, e.when or "always")
                lines.append("| " + " | ".join(_cell(f) for f in fields) + " |")
    return "\n".join(lines) + "\n"


WRITERS = {"text": to_text, "json": to_json, "dot": to_dot, "markdown": to_markdown}
