"""The Foxglove layout for ARROCH recordings and the live view (``docs/foxglove-layout.json``), in the
format the Foxglove app's and Lichtblick's "Import layout" read: their ``LayoutData``.

``LayoutData`` (Lichtblick ``packages/suite-base/src/context/CurrentLayoutContext/actions.ts``, from
Foxglove Studio): ``configById`` (each panel's config by panel id), ``layout`` (a react-mosaic tree:
a panel id, or ``{direction: row|column, first, second, splitPercentage}``), ``globalVariables``,
``userNodes`` (user scripts), ``playbackConfig`` (``{speed}``). A panel id is its type, ``!`` and any
suffix (``util/layout.ts``: ``getPanelTypeFromId``); the types are the registry's
(``panels/index.ts``: ``3D``, ``Image``, ``Plot``, ``RosOut`` for the log, ``RawMessages``). Each
config has the keys its panel reads: the 3D and Image panels a ``RendererConfig``
(``panels/ThreeDeeRender/IRenderer.ts``: ``followTf``, ``topics``, ``imageMode``, ``cameraState``
merged over ``camera.ts``'s defaults), the plot a ``PlotConfig`` (``panels/Plot/utils/config.ts``),
the log ``panels/Log/types.ts``' ``Config``, raw messages ``RawMessagesPanelConfig``; a title goes in
``foxglovePanelTitle`` (``PANEL_TITLE_CONFIG_KEY``). The SDK's own layout type
(``foxglove.layouts``) is not this format and no app's import reads it, so it is not kept.

Panels: the site in 3D (scene, paths, the camera's frustum), the tablet camera with the AR overlay,
the team's progress and door openings, the log, and the team plan.
"""

from __future__ import annotations

import json
from typing import Any

from . import topics

CAMERA = "tablet"
TITLE = "foxglovePanelTitle"
SITE_CENTRE = (10.0, 5.0, 0.0)  # the packaged office site is 20 m x 10 m


def _split(direction: str, first: Any, second: Any, percent: float) -> dict[str, Any]:
    return {"direction": direction, "first": first, "second": second, "splitPercentage": percent}


def panels() -> dict[str, dict[str, Any]]:
    """``configById``: each panel's config by its id (``<type>!<name>``)."""
    return {
        "3D!site": {
            TITLE: "site, robots, paths",
            "followTf": topics.MAP_FRAME,
            "followMode": "follow-none",
            "cameraState": {"distance": 22.0, "phi": 45.0, "thetaOffset": 0.0, "target": list(SITE_CENTRE)},
            "scene": {},
            "transforms": {},
            "layers": {},
            "topics": {
                topics.SCENE: {"visible": True},
                topics.PATHS: {"visible": True},
                # A camera calibration in the 3D panel is drawn as the camera's frustum at its frame.
                topics.camera_calibration(CAMERA): {"visible": True, "distance": 1.5, "color": "#ffffffaa"},
            },
        },
        "Image!tablet": {
            TITLE: "tablet camera with the AR overlay",
            "imageMode": {
                "imageTopic": topics.camera_image(CAMERA),
                "calibrationTopic": topics.camera_calibration(CAMERA),
                "annotations": {topics.camera_overlay(CAMERA): {"visible": True}},
            },
        },
        "Plot!progress": {
            TITLE: "team progress and door openings",
            "paths": [
                {"value": f"{topics.PROGRESS}.{key}", "enabled": True, "timestampMethod": "receiveTime", "label": text}
                for key, text in (
                    ("delivered", "objects delivered"),
                    ("door_openings", "door openings (all)"),
                    ("human_door_openings", "door openings by the human"),
                    ("open_doors", "doors open now"),
                )
            ],
            "showLegend": True,
            "legendDisplay": "floating",
            "showPlotValuesInLegend": False,
            "showXAxisLabels": True,
            "showYAxisLabels": True,
            "isSynced": True,
            "xAxisVal": "timestamp",
            "sidebarDimension": 240,
        },
        "RosOut!log": {
            TITLE: "feedback, events, service logs",
            "searchTerms": [],
            "minLogLevel": 1,
            "topicToRender": topics.LOG,
        },
        "RawMessages!plan": {
            TITLE: "team plan",
            "topicPath": topics.message_topic("plan"),
            "diffEnabled": False,
            "diffMethod": "custom",
            "diffTopicPath": "",
            "showFullMessageForDiff": False,
        },
    }


def build_layout() -> dict[str, Any]:
    """The whole ``LayoutData``."""
    left = _split("column", "3D!site", _split("row", "RosOut!log", "RawMessages!plan", 50), 72)
    right = _split("column", "Image!tablet", "Plot!progress", 60)
    return {
        "configById": panels(),
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1.0},
        "layout": _split("row", left, right, 60),
    }


def layout_json() -> str:
    """The layout as the indented JSON file kept in the repository."""
    return json.dumps(build_layout(), indent=2) + "\n"
