"""A doorway is held by one crossing robot at a time: granted to the asking robot nearest to it,
kept until the holder is through and out of the lane, and nobody else steps into the lane meanwhile."""

from __future__ import annotations

from runtime.executor.doorways import Doorways, in_lane
from tests.sim.helpers import Bot, small_site


def setup():
    site = small_site()  # d_office: an automatic door at (3, 6), corridor below it, office above
    fleet = {
        "r0": Bot("r0", 3.0, 4.4),  # 1.6 m below the door, off its lane
        "r1": Bot("r1", 3.0, 7.7),  # 1.7 m above it
        "r2": Bot("r2", 5.0, 5.0),  # passing by in the corridor
    }
    return Doorways(site), site.opening("d_office"), fleet


def test_the_nearest_asking_robot_gets_the_doorway_and_the_other_waits():
    ways, door, fleet = setup()
    fleet["r2"].x, fleet["r2"].y = 3.0, 5.7  # r2 crosses first, in the lane
    assert ways.may_cross(fleet["r2"], "d_office", 0.0, fleet)
    assert not ways.may_cross(fleet["r1"], "d_office", 0.0, fleet)  # r1 asks first ...
    assert not ways.may_cross(fleet["r0"], "d_office", 1.0, fleet)  # ... r0 later
    fleet["r2"].y = 7.5  # r2 is through and out of the lane
    assert not ways.may_cross(fleet["r1"], "d_office", 2.0, fleet)  # r0 is nearer: r0 first
    assert ways.may_cross(fleet["r0"], "d_office", 2.0, fleet)
    assert ways.holders == {"d_office": "r0"}


def test_a_nearer_robot_takes_over_only_while_the_holder_has_not_set_off():
    ways, door, fleet = setup()
    fleet["r0"].y = 4.2  # 1.8 m below the door
    assert ways.may_cross(fleet["r1"], "d_office", 0.0, fleet)  # r1, 1.7 m above it, alone: granted
    fleet["r0"].y = 4.4  # r0 now nearer while r1 has not moved: r0 stands in its way, it goes first
    assert ways.may_cross(fleet["r0"], "d_office", 1.0, fleet)
    assert not ways.may_cross(fleet["r1"], "d_office", 1.0, fleet)
    fleet["r0"].x = 3.3  # r0 on its way (0.3 m from where it got the doorway), still out of the lane:
    fleet["r1"].y = 7.3  # it keeps the doorway though r1 is nearer now
    assert not ways.may_cross(fleet["r1"], "d_office", 2.0, fleet)
    fleet["r0"].y = 5.6  # r0 in the lane: it keeps it whoever comes nearer
    ways.may_cross(fleet["r0"], "d_office", 3.0, fleet)
    fleet["r1"].y = 6.3
    assert not ways.may_cross(fleet["r1"], "d_office", 3.0, fleet)


def test_nobody_steps_into_a_held_lane_and_the_holder_lets_go_once_through():
    ways, door, fleet = setup()
    fleet["r0"].y = 5.6
    assert ways.may_cross(fleet["r0"], "d_office", 0.0, fleet)
    assert in_lane(door, 3.0, 5.0) and not in_lane(door, 5.0, 5.0)
    assert ways.lane_taken(fleet["r2"], 3.2, 5.0, fleet)  # r2 would step into it: no
    assert not ways.lane_taken(fleet["r2"], 4.5, 5.0, fleet)  # along the corridor beside it: yes
    assert not ways.lane_taken(fleet["r0"], 3.0, 6.0, fleet)  # the holder goes on
    fleet["r0"].y = 7.4  # through, and out of the lane (1.2 m deep)
    assert not ways.lane_taken(fleet["r2"], 3.2, 5.0, fleet) and ways.holders == {}
    assert ways.may_cross(fleet["r1"], "d_office", 3.0, fleet)


def test_a_holder_told_something_else_or_stopped_lets_go():
    ways, door, fleet = setup()
    fleet["r0"].y = 5.6
    assert ways.may_cross(fleet["r0"], "d_office", 0.0, fleet)
    ways.forget("r0")  # a new command
    assert ways.may_cross(fleet["r1"], "d_office", 1.0, fleet)
    fleet["r1"].phase = "done"
    assert not ways.lane_taken(fleet["r2"], 3.2, 5.0, fleet) and ways.holders == {}
