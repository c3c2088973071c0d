"""What the Foxglove app and Lichtblick accept, as their sources say, for tests to hold our files to.

No app runs here: the rules are read off Lichtblick's sources (``Lichtblick-Suite/lichtblick``, the
open fork of Foxglove Studio whose formats the Foxglove app shares), and each function names its file.
"""

from __future__ import annotations

from typing import Any

# packages/suite-base/src/panels/index.ts: the registry's panel types (those the layout uses and more).
PANEL_TYPES = {
    "3D",
    "Image",
    "Plot",
    "RosOut",
    "RawMessages",
    "Indicator",
    "Gauge",
    "map",
    "Table",
    "StateTransitions",
    "SourceInfo",
    "Tab",
}
# The keys each panel's config is read with (the types named in the layout module's docstring).
# panels/ThreeDeeRender/IRenderer.ts: RendererConfig (the Image panel is the same renderer in image mode)
RENDERER_KEYS = {"cameraState", "followMode", "followTf", "scene", "transforms", "topics", "layers", "publish"}
RENDERER_KEYS |= {"imageMode"}
PANEL_KEYS = {
    "3D": RENDERER_KEYS,
    "Image": RENDERER_KEYS,
    "Plot": {
        "paths",
        "minXValue",
        "maxXValue",
        "minYValue",
        "maxYValue",
        "showLegend",
        "legendDisplay",
        "showPlotValuesInLegend",
        "showXAxisLabels",
        "showYAxisLabels",
        "isSynced",
        "xAxisVal",
        "xAxisPath",
        "followingViewWidth",
        "sidebarDimension",
    },
    "RosOut": {"searchTerms", "minLogLevel", "topicToRender", "nameFilter"},
    "RawMessages": {
        "diffEnabled",
        "diffMethod",
        "diffTopicPath",
        "expansion",
        "showFullMessageForDiff",
        "topicPath",
        "fontSize",
    },
}
TITLE_KEY = "foxglovePanelTitle"  # util/layout.ts: PANEL_TITLE_CONFIG_KEY
CAMERA_STATE_KEYS = {  # panels/ThreeDeeRender/camera.ts: CameraState
    "distance",
    "perspective",
    "phi",
    "target",
    "targetOffset",
    "targetOrientation",
    "thetaOffset",
    "fovy",
    "near",
    "far",
}


def json_schema_problems(schema: Any, path: str = "") -> list[str]:
    """What ``parseJsonSchema`` (packages/mcap-support/src/parseJsonSchema.ts) would refuse in a
    channel's JSON Schema; it refuses the whole channel for any of them."""
    if not isinstance(schema, dict) or schema.get("type") != "object":
        return [f'{path or "root"}: expected "type": "object"']
    problems = []
    for name, sub in (schema.get("properties") or {}).items():
        where = f"{path}.{name}" if path else name
        if not isinstance(sub, dict):
            problems.append(f"{where}: not a schema")
            continue
        if isinstance(sub.get("oneOf"), list):
            if not all(isinstance(alt, dict) and isinstance(alt.get("const"), (int, float)) for alt in sub["oneOf"]):
                problems.append(f"{where}: oneOf alternatives must have number values")
            continue
        kind = sub.get("type")
        if kind == "object":
            problems += json_schema_problems(sub, where)
        elif kind == "array":
            items = sub.get("items")
            item_kind = items.get("type") if isinstance(items, dict) else None
            if item_kind == "object":
                problems += json_schema_problems(items, f"{where}[]")
            elif item_kind not in ("boolean", "string", "number", "integer"):
                problems.append(f"{where}: array items of type {item_kind!r}")
            elif item_kind == "string" and items.get("contentEncoding") is not None:
                problems.append(f"{where}: contentEncoding in array items")
        elif kind == "string":
            if sub.get("contentEncoding") not in (None, "base64"):
                problems.append(f"{where}: contentEncoding {sub['contentEncoding']!r}")
        elif kind not in ("boolean", "number", "integer"):
            problems.append(f"{where}: type {kind!r}")
    return problems


def _leaves(node: Any, path: str, problems: list[str]) -> list[str]:
    """The panel ids of a react-mosaic tree (a panel id, or ``{direction, first, second, splitPercentage?}``)."""
    if isinstance(node, str):
        return [node]
    if not isinstance(node, dict) or set(node) - {"direction", "first", "second", "splitPercentage"}:
        problems.append(f"{path}: not a mosaic node: {node!r}"[:200])
        return []
    if node.get("direction") not in ("row", "column"):
        problems.append(f"{path}.direction: {node.get('direction')!r}")
    if "splitPercentage" in node and not 0 < node["splitPercentage"] < 100:
        problems.append(f"{path}.splitPercentage: {node['splitPercentage']!r}")
    first = _leaves(node.get("first"), f"{path}.first", problems)
    return first + _leaves(node.get("second"), f"{path}.second", problems)


def layout_problems(layout: Any) -> list[str]:
    """What keeps a file from importing as ``LayoutData`` (context/CurrentLayoutContext/actions.ts) with
    every panel shown and configured."""
    if not isinstance(layout, dict):
        return ["not a JSON object"]
    needed = ("configById", "layout", "globalVariables", "userNodes")
    problems = [f"missing {key}" for key in needed if key not in layout]
    if problems:
        return problems
    speed = (layout.get("playbackConfig") or {}).get("speed", 1)
    if not isinstance(speed, (int, float)) or speed <= 0:
        problems.append(f"playbackConfig.speed: {speed!r}")
    ids = _leaves(layout["layout"], "layout", problems)
    configs = layout["configById"]
    if sorted(ids) != sorted(configs):
        problems.append(f"panels in the tree {sorted(ids)} are not those configured {sorted(configs)}")
    for panel_id in ids:
        kind = panel_id.split("!")[0]  # util/layout.ts: getPanelTypeFromId
        if "!" not in panel_id or kind not in PANEL_TYPES:
            problems.append(f"{panel_id}: not a panel id of a known type")
            continue
        config = configs.get(panel_id, {})
        unknown = set(config) - PANEL_KEYS.get(kind, set()) - {TITLE_KEY}
        if unknown:
            problems.append(f"{panel_id}: keys its panel does not read: {sorted(unknown)}")
        if set(config.get("cameraState", {})) - CAMERA_STATE_KEYS:
            problems.append(f"{panel_id}.cameraState: unknown keys")
    return problems
