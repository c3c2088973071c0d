"""``arroch ros2 bridge``: the team's state for RViz 2 and ROS 2 tools (see docs/ros2.md)."""
