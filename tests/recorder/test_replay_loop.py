"""``arroch replay --loop``: each pass after the first goes out re-timed (every site time later, the
sender renamed), so receivers that drop what is older than what they have take it as news."""

from __future__ import annotations

from protocol.codec import decode, encode
from protocol.messages import Clock, DoorState, Intent, RobotPose
from services.recorder.reading import Recorded
from services.recorder.replay import retimed


def recorded(msg, topic: str = "/arroch/x") -> Recorded:  # noqa: ANN001
    return Recorded(topic, msg.stamp, encode(msg), msg)


def stamped(msg, stamp: float):  # noqa: ANN001, ANN201
    msg.src, msg.seq, msg.stamp = "sim-1", 7, stamp
    return msg


def test_a_later_pass_shifts_every_site_time_and_renames_the_sender():
    clock = retimed(recorded(stamped(Clock(time=12.0, mode="lockstep"), 12.0)), 700.0, "~1")
    assert (clock.time, clock.message.time, clock.message.stamp) == (712.0, 712.0, 712.0)
    assert (clock.message.src, clock.message.seq) == ("sim-1~1", 7)
    assert decode(clock.payload, Clock) == clock.message  # the bytes sent are the re-timed message

    intent = retimed(recorded(stamped(Intent(robot="r0", trajectory=[[12.0, 1.0, 2.0, 0.5]]), 12.0)), 700.0, "~1")
    assert intent.message.trajectory == [[712.0, 1.0, 2.0, 0.5]]
    door = retimed(recorded(stamped(DoorState(door="d", open=True, until=30.0), 12.0)), 700.0, "~2")
    assert (door.message.until, door.message.src) == (730.0, "sim-1~2")
    unknown_end = retimed(recorded(stamped(DoorState(door="d", open=True), 12.0)), 700.0, "~2")
    assert unknown_end.message.until == 0.0  # 0: no deadline known, kept so
    pose = retimed(recorded(stamped(RobotPose(robot="r0", x=1.0, y=2.0, theta=0.0), 3.0)), 700.0, "~1")
    assert (pose.message.stamp, pose.message.x) == (703.0, 1.0)
