"""A small site for missions through ROS 2 that need not be the default one."""

# A corridor and her storage room behind the human-operated d_storage; two robots, each to bring one
# object from the corridor into her room, so each must wait for her door.
SITE_TOML = """
[site]
name = "rehearsal"

[params]
robot_speed = 0.5
robot_radius = 0.25
load_time = 2.0
door_hold_time = 20.0
robot_capacity = 1

[[rooms]]
id = "corridor"
rect = [0.0, 4.0, 12.0, 6.0]

[[rooms]]
id = "storage"
rect = [4.0, 0.0, 8.0, 4.0]

[[doors]]
id = "d_storage"
rooms = ["corridor", "storage"]
center = [6.0, 4.0]
width = 0.9
human_operated = true

[[robots]]
id = "r0"
start = [1.5, 5.0, 0.0]

[[robots]]
id = "r1"
start = [10.5, 5.0, 3.14159]

[[objects]]
id = "o0"
position = [3.0, 5.0]
deliver_to = "storage"
robot = "r0"

[[objects]]
id = "o1"
position = [9.0, 5.0]
deliver_to = "storage"
robot = "r1"

[human]
room = "storage"
position = [7.0, 1.0]
"""
