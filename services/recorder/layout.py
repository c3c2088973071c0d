"""The Foxglove layout for ARROCH recordings and the live view (``docs/foxglove-layout.json``).

Built with ``foxglove.layouts`` (the SDK's layout types), so the file follows Foxglove's schema:
a 3D panel (site, robots, paths, camera frustum), the tablet camera with the AR overlay drawn over it,
a plot of the team's progress and door openings, the log, and the team plan.
"""

from __future__ import annotations

import json

import foxglove.layouts as fl

from . import topics

CAMERA = "tablet"


def build_layout() -> fl.Layout:
    scene = fl.ThreeDeePanel(
        title="site, robots, paths",
        config=fl.ThreeDeeConfig(
            follow_tf=topics.WORLD_FRAME,
            fixed_frame=topics.WORLD_FRAME,
            follow_mode="follow-none",
            topics={
                topics.SCENE: fl.BaseRendererSceneUpdateTopicSettings(visible=True),
                topics.PATHS: fl.BaseRendererSceneUpdateTopicSettings(visible=True),
                # A camera calibration in the 3D panel is drawn as the camera's frustum at its frame.
                topics.camera_calibration(CAMERA): fl.BaseRendererCameraTopicSettings(
                    visible=True, distance=1.5, color="#ffffffaa"
                ),
            },
        ),
    )
    camera = fl.ImagePanel(
        title="tablet camera with the AR overlay",
        config=fl.ImageConfig(
            image_mode=fl.ImageModeConfig(
                image_topic=topics.camera_image(CAMERA),
                calibration_topic=topics.camera_calibration(CAMERA),
                annotations={topics.camera_overlay(CAMERA): fl.ImageAnnotationSettings(visible=True)},
            )
        ),
    )
    progress = fl.PlotPanel(
        title="team progress and door openings",
        config=fl.PlotConfig(
            paths=[
                fl.PlotSeries(value=f"{topics.PROGRESS}.delivered", label="objects delivered"),
                fl.PlotSeries(value=f"{topics.PROGRESS}.door_openings", label="door openings (all)"),
                fl.PlotSeries(value=f"{topics.PROGRESS}.human_door_openings", label="door openings by the human"),
                fl.PlotSeries(value=f"{topics.PROGRESS}.open_doors", label="doors open now"),
            ],
            show_legend=True,
            x_axis_val="timestamp",
        ),
    )
    log = fl.LogPanel(title="feedback, events, service logs", config=fl.LogConfig(topic_to_render=topics.LOG))
    plan = fl.RawMessagesPanel(title="team plan", config=fl.RawMessagesConfig(topic_path=topics.PLAN))
    right = fl.SplitContainer(
        direction="column",
        items=[fl.SplitItem(proportion=3, content=camera), fl.SplitItem(proportion=2, content=progress)],
    )
    bottom = fl.SplitContainer(direction="row", items=[fl.SplitItem(content=log), fl.SplitItem(content=plan)])
    left = fl.SplitContainer(
        direction="column",
        items=[fl.SplitItem(proportion=3, content=scene), fl.SplitItem(proportion=1, content=bottom)],
    )
    return fl.Layout(
        content=fl.SplitContainer(
            direction="row", items=[fl.SplitItem(proportion=3, content=left), fl.SplitItem(proportion=2, content=right)]
        )
    )


def layout_json() -> str:
    """The layout as the indented JSON file kept in the repository."""
    return json.dumps(json.loads(build_layout().to_json()), indent=2, sort_keys=True) + "\n"
