"""Lockstep's held camera frames (services/sim/camfeed.py ``FrameHold``): a frame every
``--camera-hold`` site seconds, time standing still until its overlay comes back or a wall timeout
passes, the wall rate as a fallback when no AR client answers, and back to holds when one does.

The rules are checked on :class:`FrameHold` alone (pure), then on a real ``arroch sim`` process in
lockstep driven by the planner stand-in, with this test playing the AR client on the wire."""

from __future__ import annotations

import argparse
import queue
import time

import pytest

from protocol.messages import CameraFrame, Clock, Event, Overlay, RobotPose
from protocol.site import load_site
from services.sim.camfeed import MAX_MISSED, FrameHold, add_camera_arguments, camera_options_from
from tests.conftest import wait_for_message
from tests.sim.standin import StandInPlanner
from tests.sim.test_sim_service import Running, drain, sim_argv

# ---------------------------------------------------------------------- the rules, pure


def test_holds_fall_at_the_first_tick_at_or_past_each_multiple_of_the_interval():
    hold = FrameHold(20.0, 1.5)
    assert hold.due(0.0)
    hold.begin(0.0, wall=100.0)
    assert not hold.due(25.0)  # one hold at a time
    hold.framed(7, wall=100.1)
    assert hold.blocker() == "camera frame 7 awaiting its overlay"
    assert hold.overlay(7, wall=100.2) and hold.blocker() == ""
    assert not hold.due(19.95) and hold.due(20.0 - 1e-9)  # a rounding error short of 20 is at 20
    hold.begin(20.05, wall=101.0)  # the tick past 20 (a tick of 0.05)...
    assert hold.next_at == 40.0  # ...keeps the grid: the next one is at 40, not 40.05
    assert (hold.held, hold.released, hold.timed_out) == (2, 1, 0)


def test_only_the_held_frames_overlay_releases_it_and_a_timeout_ends_it_too():
    hold = FrameHold(10.0, 1.5)
    hold.begin(0.0, wall=0.0)
    assert hold.blocker() == "camera frame (rendering) awaiting its overlay"
    assert not hold.overlay(3, wall=0.05)  # an overlay before the frame is out: not this frame's
    hold.framed(5, wall=0.1)
    assert not hold.overlay(4, wall=0.2) and hold.active  # an older frame's overlay
    assert not hold.expired(1.55) and hold.active  # counted from the frame's publication, not its rendering
    assert hold.expired(1.6) and not hold.active and hold.blocker() == ""
    assert not hold.expired(9.0)  # nothing held any more
    assert (hold.timed_out, hold.missed) == (1, 1)
    assert not hold.overlay(5, wall=2.0)  # the late overlay releases nothing, but shows an AR client is there
    assert hold.missed == 0


def test_holds_are_suspended_after_missed_overlays_and_resume_with_the_next_overlay():
    hold = FrameHold(10.0, 1.0)
    for k in range(MAX_MISSED):
        assert not hold.suspended and hold.due(10.0 * k)
        hold.begin(10.0 * k, wall=float(k))
        hold.framed(k, wall=float(k))
        assert hold.expired(k + 1.0)
    assert hold.suspended and hold.due(10.0 * MAX_MISSED)
    hold.skip(10.0 * MAX_MISSED + 3.0)  # suspended: the instant passes without a hold
    assert not hold.due(10.0 * MAX_MISSED + 9.0) and hold.due(10.0 * (MAX_MISSED + 1))
    hold.overlay(99, wall=50.0)  # a wall-rate frame's overlay
    assert not hold.suspended and hold.held == MAX_MISSED


@pytest.mark.parametrize(
    "args, message",
    [
        (["--camera-hold", "-1"], "--camera-hold must be >= 0"),
        (["--camera-hold", "nan"], "--camera-hold must be >= 0"),
        (["--camera-hold-timeout", "0"], "--camera-hold-timeout must be > 0"),
        (["--camera-every", "-2"], "--camera-every must be >= 0"),
        (["--camera-every", "inf"], "--camera-every must be >= 0"),
    ],
)
def test_bad_hold_options_are_refused_naming_the_option(args, message):
    parser = argparse.ArgumentParser()
    add_camera_arguments(parser)
    with pytest.raises(ValueError, match=message):
        camera_options_from(parser.parse_args(["--camera", "tablet", *args]))


def test_hold_options_default_to_a_hold_every_30_site_seconds_and_no_frames_between():
    parser = argparse.ArgumentParser()
    add_camera_arguments(parser)
    options = camera_options_from(parser.parse_args(["--camera", "tablet"]))
    assert (options.hold, options.hold_timeout, options.every) == (30.0, 5.0, 0.0)  # frames cost CPU: none asked
    every = camera_options_from(parser.parse_args(["--camera", "tablet", "--camera-every", "2"])).every
    assert every == 2.0  # what arroch demo asks for: 0.5 Hz of site time
    assert camera_options_from(parser.parse_args(["--camera", "tablet", "--camera-hold", "0"])).hold == 0.0


# ---------------------------------------------------------------------- the real sim loop

HOLD = 5.0  # site s
TIMEOUT = 1.2  # wall s
ANSWER_AFTER = 0.6  # wall s the test (as AR client) takes to answer a frame: past a paused-clock heartbeat (0.5 s)
RATE = 10.0  # wall-rate frames per second once the holds are suspended
# Lockstep runs free at ~500-900 site s per wall s here while the holds are suspended: a long task
# of the human's keeps the mission going (and its frames coming) however fast the machine is.
LONG_MISSION = "[human]\ntask_mean = 4000.0\ntask_std = 0.0\nfocus_count = 0\n"


def next_frame(frames: queue.Queue, timeout: float = 10.0) -> tuple[CameraFrame, float]:
    """The next frame and the wall time it arrived."""
    frame = wait_for_message(frames, timeout=timeout)
    return frame, time.monotonic()


def on_grid(t: float) -> bool:
    return abs(t - HOLD * round(t / HOLD)) < 1e-6


@pytest.mark.integration
def test_lockstep_holds_time_for_each_frames_overlay_then_times_out_then_falls_back_and_resumes(
    router, client, spawn, tmp_path
):
    namespace = client.keys.site
    human = tmp_path / "human.toml"
    human.write_text(LONG_MISSION)
    frames = client.collect(client.keys.camera_frame("tab"), CameraFrame)
    clocks = client.collect(client.keys.clock(), Clock)
    poses = client.collect(client.keys.robot_pose(), RobotPose)

    def answer(frame: CameraFrame) -> None:
        client.publish(client.keys.overlay("tab"), Overlay(camera="tab", frame_seq=frame.seq))

    sim = spawn(
        sim_argv(
            router,
            namespace,
            "--mode",
            "lockstep",
            "--seed",
            "3",
            "--human-config",
            str(human),
            "--camera",
            "tablet",
            "--camera-id",
            "tab",
            "--camera-size",
            "160x120",
            "--camera-rate",
            str(RATE),
            "--camera-hold",
            str(HOLD),
            "--camera-every",  # no frames between the held ones: each frame seen here is a held one
            str(HOLD),
            "--camera-hold-timeout",
            str(TIMEOUT),
        ),
        name="sim",
    )
    sim.wait_for("up on namespace", timeout=30)
    # No planner yet: the hold at t=0 waits for the plan answering t=0, so that its frame is drawn
    # with the robots' paths of that instant; no frame meanwhile.
    wait_for_message(clocks, lambda c: c.paused and c.time == 0.0, timeout=10)
    time.sleep(0.8)
    assert frames.empty()
    with Running(StandInPlanner(load_site(None), namespace, router)):
        # 1. Answered after a while: each frame is at the next multiple of HOLD, and time stands
        # still at the frame's instant until its overlay comes back, then runs on.
        expected = 0.0
        for _ in range(4):
            frame, _arrived = next_frame(frames)
            assert frame.stamp == pytest.approx(expected, abs=1e-6), (frame.stamp, expected)
            time.sleep(ANSWER_AFTER)
            seen = [(c.time, c.paused) for c in drain(clocks)]  # since the last answer
            assert all(t <= frame.stamp for t, _ in seen), seen
            assert seen.count((frame.stamp, True)) >= 2, seen  # before the frame, and the heartbeat while held
            answer(frame)
            expected += HOLD  # the very next frame: no wall-rate frame in between
        # The robots' poses of a held instant went out with its frame (the AR client draws them).
        stamps = {(p.robot, p.stamp) for p in drain(poses)}
        assert {(rid, HOLD) for rid in ("r0", "r1", "r2")} <= stamps

        # 2. Not answered: time stands still at the frame for the timeout, then goes on; after
        # MAX_MISSED such frames the camera renders at the wall rate instead (--camera-rate).
        for _ in range(MAX_MISSED):
            frame, arrived = next_frame(frames)
            assert on_grid(frame.stamp)
            moved = wait_for_message(clocks, lambda c, held=frame.stamp: c.time > held, timeout=10)
            waited = time.monotonic() - arrived
            assert 0.8 * TIMEOUT <= waited <= TIMEOUT + 1.0, waited
            assert moved.time <= frame.stamp + HOLD + 1e-6  # stopped again at the next hold instant at the latest
        sim.wait_for("got no overlay on", timeout=5)
        loose = [next_frame(frames) for _ in range(4)]
        rate = 3 / (loose[-1][1] - loose[0][1])
        assert 0.5 * RATE <= rate <= 1.5 * RATE, rate
        loose = [frame for frame, _ in loose]
        assert not all(on_grid(f.stamp) for f in loose), [f.stamp for f in loose]  # at wall instants now

        # 3. An overlay again (of a wall-rate frame): the holds resume on the grid.
        answer(loose[-1])
        sim.wait_for("come again", timeout=5)
        frame = wait_for_message(frames, lambda f: on_grid(f.stamp) and f.stamp > loose[-1].stamp, timeout=10)
        time.sleep(ANSWER_AFTER)
        assert all(c.time <= frame.stamp for c in drain(clocks))
        answer(frame)
        wait_for_message(clocks, lambda c: c.time > frame.stamp, timeout=10)
    assert sim.output.count("got no overlay on") == 1  # said once
    (stats,) = client.query(client.keys.stats("sim"), Event, timeout=5)
    assert stats.data["camera_holds_released"] >= 5 and stats.data["camera_holds_timed_out"] >= MAX_MISSED
