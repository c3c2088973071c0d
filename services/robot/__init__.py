"""``arroch robot --ros2``: one real robot driven through ROS 2 (see docs/ros2.md)."""
