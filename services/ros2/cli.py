"""Command line: ``arroch ros2 bridge [--ros2-config FILE] [--key-format F] [--domain N] [--ros-namespace NS]``.

The config's ``[ros2.doors.<door>]`` tables name the real doors' sensors it forwards; a door the
site lacks, or an automatic one, is a configuration error (exit 2)."""

from __future__ import annotations

import argparse
from typing import Any

from runtime.ros2.config import add_ros2_link_arguments, ros2_config_from
from runtime.runner import add_common_arguments, run_service


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("ros2", help="ROS 2 tools: the state bridge for RViz 2")
    sub = parser.add_subparsers(dest="ros2_command", metavar="SUBCOMMAND")
    bridge = sub.add_parser(
        "bridge",
        help="publish the team's state as ROS 2 topics (tf, paths, site markers) and take feedback from ROS 2",
        description=(
            "Publishes tf2_msgs/TFMessage (map -> <robot>/base_link), nav_msgs/Path per robot's intent and a "
            "visualization_msgs/MarkerArray of the site (walls, doors with state, tags, objects) over Zenoh in "
            "rmw_zenoh's or zenoh-bridge-ros2dds's key format; std_msgs/String JSON feedback in, acks out; "
            "std_msgs/Bool door sensors in (the config's [ros2.doors.<door>] topics) as DoorState on "
            "door/<door>/sensor."
        ),
    )
    add_common_arguments(bridge)
    add_ros2_link_arguments(bridge)
    bridge.add_argument(
        "--ros-namespace",
        default="/arroch",
        metavar="NS",
        help="ROS namespace of the bridge's topics (default /arroch)",
    )
    bridge.add_argument(
        "--map-frame", default="map", metavar="FRAME", help="frame of everything published (default map)"
    )
    bridge.set_defaults(func=_run)
    parser.set_defaults(func=lambda args: parser.print_help() or 2)


def _run(args: argparse.Namespace) -> int:
    def build() -> Any:
        from protocol.site import load_site
        from runtime.clock import make_clock
        from runtime.ros2.config import check_doors
        from runtime.ros2.keys import full_topic
        from runtime.transport import options_from

        from .bridge import BridgeService

        full_topic("/", args.ros_namespace.strip("/") or "arroch")  # ValueError (exit 2) for a bad namespace
        site = load_site(args.site)
        config = ros2_config_from(args)
        check_doors(config, site)
        return BridgeService(
            site,
            config.naming(),
            options_from(args),
            namespace=args.namespace,
            ros_namespace=args.ros_namespace,
            map_frame=args.map_frame,
            clock=make_clock(args.clock),
            door_topics={did: link.topic for did, link in config.doors.items()},
        )

    return run_service(build)
