"""ROS 2 on Zenoh without linking ROS: CDR messages (``rosbags``), key expressions in the two
formats ROS 2 uses on Zenoh (``rmw_zenoh`` and ``zenoh-bridge-ros2dds``), ``rmw_zenoh``'s
per-sample attachment and its liveliness tokens (graph discovery). See docs/ros2.md.

| module | responsibility |
|---|---|
| ``types.py`` | the typestore, the ROS types ARROCH uses with their RIHS01 hashes, CDR in and out, message builders |
| ``keys.py`` | ``TopicNaming``: data keys and liveliness tokens for a topic, in either key format |
| ``attachment.py`` | ``rmw_zenoh``'s attachment: sequence number, source timestamp, publisher GID |
| ``node.py`` | ``RosNode``: ROS publishers/subscriptions on a :class:`runtime.service.Service`'s session |
| ``config.py`` | the ``[ros2]``, ``[ros2.robots.<id>]`` and ``[ros2.doors.<id>]`` sections of a robot config file |
"""
