"""The site clock: wall time, and sim time from Clock messages (extrapolated, or not in lockstep)."""

from __future__ import annotations

import time

import pytest

from protocol.messages import Clock
from runtime import clock as clock_module
from runtime.clock import MAX_EXTRAPOLATION, SimClock, WallClock, make_clock


class FakeMonotonic:
    """Stands in for time.monotonic inside runtime.clock, so extrapolation is checked exactly."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def mono(monkeypatch) -> FakeMonotonic:
    fake = FakeMonotonic()
    monkeypatch.setattr(clock_module.time, "monotonic", fake)
    return fake


def tick(
    time_: float,
    *,
    mode: str = "realtime",
    rate: float = 1.0,
    src: str = "sim-1",
    seq: int = 1,
    paused: bool = False,
    world_version: int = 0,
) -> Clock:
    return Clock(time=time_, mode=mode, rate=rate, src=src, seq=seq, paused=paused, world_version=world_version)


def test_wall_clock_is_unix_time():
    clock = WallClock()
    before = time.time()
    assert before <= clock.now() <= time.time()
    assert clock.synced


def test_make_clock():
    assert isinstance(make_clock("wall"), WallClock)
    assert isinstance(make_clock("sim"), SimClock)
    with pytest.raises(ValueError):
        make_clock("sundial")


def test_sim_clock_before_any_message():
    clock = SimClock()
    assert not clock.synced and clock.now() == 0.0


@pytest.mark.parametrize("mode,rate", [("realtime", 1.0), ("rate", 5.0), ("wall", 1.0)])
def test_sim_time_is_extrapolated_at_the_rate(mono, mode, rate):
    clock = SimClock()
    clock.update(tick(100.0, mode=mode, rate=rate))
    assert clock.synced and clock.now() == 100.0
    mono.now += 0.2
    assert clock.now() == pytest.approx(100.0 + 0.2 * rate)


def test_extrapolation_stops_a_second_after_the_last_message(mono):
    clock = SimClock()
    clock.update(tick(50.0, rate=2.0))
    mono.now += 30.0  # the sim stalled
    assert clock.now() == pytest.approx(50.0 + MAX_EXTRAPOLATION * 2.0)


@pytest.mark.parametrize("lockstep", [True, False], ids=["lockstep", "paused"])
def test_no_extrapolation_in_lockstep_or_paused(mono, lockstep):
    clock = SimClock()
    clock.update(tick(10.0, mode="lockstep") if lockstep else tick(10.0, paused=True))
    mono.now += 5.0
    assert clock.now() == 10.0
    clock.update(tick(10.5, mode="lockstep", seq=2) if lockstep else tick(10.5, paused=True, seq=2))
    assert clock.now() == 10.5  # moves only when the sim says so


def test_old_messages_from_the_same_sender_are_ignored(mono):
    clock = SimClock()
    clock.update(tick(20.0, seq=5, world_version=3))
    clock.update(tick(19.0, seq=4, world_version=2))  # overtaken on the way
    assert clock.now() == 20.0 and clock.world_version == 3
    clock.update(tick(20.0, seq=5))  # a repeat
    clock.update(tick(21.0, seq=6, world_version=4))
    assert clock.now() == 21.0 and clock.world_version == 4


def test_a_new_sender_resets_the_clock(mono):
    """A restarted sim (new src) starts again from 0: the clock follows it rather than freezing."""
    clock = SimClock()
    clock.update(tick(500.0, src="sim-100", seq=900, world_version=40))
    clock.update(tick(0.0, src="sim-200", seq=1, world_version=1))
    assert clock.now() == 0.0 and clock.world_version == 1


def test_same_sender_may_move_time_back_on_purpose(mono):
    clock = SimClock()
    clock.update(tick(300.0, seq=10))
    clock.update(tick(0.0, seq=11))  # e.g. a new mission in the same sim process
    assert clock.now() == 0.0


def test_unstamped_messages_are_ordered_by_time(mono):
    clock = SimClock()
    clock.update(Clock(time=5.0))
    clock.update(Clock(time=4.0))
    assert clock.now() == 5.0
    clock.update(Clock(time=4.0, mode="lockstep"))  # a mode change is always taken
    assert clock.now() == 4.0 and clock.mode == "lockstep"


def test_world_version_never_goes_back_for_one_sender(mono):
    clock = SimClock()
    clock.update(tick(1.0, seq=1, world_version=7))
    clock.update(tick(2.0, seq=2, world_version=5))
    assert clock.world_version == 7
