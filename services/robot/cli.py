"""Command line: ``arroch robot --ros2 --robot ID [--ros2-config FILE] [--key-format F] [--domain N]``.

One process per real robot. Bad configuration (site, robot id, config file) exits 2 before any
Zenoh session is opened.
"""

from __future__ import annotations

import argparse
from typing import Any

from runtime.ros2.config import add_ros2_link_arguments, ros2_config_from
from runtime.runner import add_common_arguments, run_service


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "robot",
        help="drive one real robot through ROS 2 (cmd_vel out, odometry/localisation in)",
        description=(
            "Execute this robot's RobotCommands with the simulator's executor (runtime/executor: pure pursuit, "
            "holds, doors, and the traffic rules that keep robots apart, over the other robots' poses, statuses "
            "and RobotTraffic), sending geometry_msgs/Twist on its cmd_vel and reading its pose from "
            "nav_msgs/Odometry or geometry_msgs/PoseWithCovarianceStamped, over Zenoh in rmw_zenoh's or "
            "zenoh-bridge-ros2dds's key format. Publishes RobotPose, RobotStatus and RobotTraffic. Stops the robot "
            "when its command ends or is refused, at a closed door, for another robot, when its pose goes stale, "
            "when the planner dies, on SIGTERM."
        ),
    )
    add_common_arguments(parser)
    parser.add_argument(
        "--ros2", action="store_true", required=True, help="drive the robot through ROS 2 (the only link for now)"
    )
    parser.add_argument("--robot", required=True, metavar="ID", help="the robot's id in the site file")
    add_ros2_link_arguments(parser)
    parser.add_argument(
        "--no-planner-hold", action="store_true", help="keep executing the current command when the planner goes away"
    )
    parser.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    def build() -> Any:
        from protocol.site import load_site
        from runtime.clock import make_clock
        from runtime.transport import options_from

        from .service import RobotOptions, RobotService

        site = load_site(args.site)
        config = ros2_config_from(args)
        return RobotService(
            site,
            args.robot,
            config.link(args.robot),
            config.naming(args.robot),
            options_from(args),
            namespace=args.namespace,
            clock=make_clock(args.clock),
            options=RobotOptions(hold_without_planner=not args.no_planner_hold),
        )

    return run_service(build)
