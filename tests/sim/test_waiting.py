"""A robot kept back by robots gives up only when its wait cannot end by itself (services/sim/waiting.py)."""

from __future__ import annotations

import math

from runtime.executor.waiting import Waits
from tests.sim.helpers import PASSIVE, Bot, command
from tests.sim.test_make_way import crowd_engine


def fleet(**phases: str) -> dict[str, Bot]:
    return {rid: Bot(rid, float(i), 0.0, phase) for i, (rid, phase) in enumerate(phases.items())}


def test_a_queue_is_not_stuck_a_cycle_a_parked_robot_or_nobody_is():
    waits = Waits()
    robots = fleet(r0="drive", r1="drive", r2="drive", r3="done")
    waits.on("r0", "r1")
    waits.on("r1", "r2")  # r2 waits for no robot (a door, a hold, or it drives): a queue behind it
    assert not waits.stuck("r0", robots)
    waits.on("r2", "r0")  # each waits on the next
    assert waits.stuck("r0", robots) and waits.stuck("r1", robots)
    waits.on("r2", "r3")  # behind a parked robot that did not make way
    assert waits.stuck("r0", robots)
    waits.off("r0")
    assert waits.stuck("r0", robots)  # kept back, and nobody noted: not known to be a queue


def test_a_robot_behind_one_waiting_for_a_door_to_open_queues_and_goes_on_once_it_opens():
    # r0 has approached the shut storage door and waits for the human to open it (opendoor; she
    # does not); r1 approaches the door to where r0 stands, in the doorway's lane (so it does not
    # call its approach done behind r0), and is kept back by r0, which does not make way (here: r1
    # does not ask). r1 waits there - far longer than Avoidance.give_up (12 s), after which it used
    # to fail, and longer than Waits.patience (120 s: she may have declared herself unavailable for
    # minutes) - and gets there once r0 has gone through.
    e = crowd_engine({}, PASSIVE)
    e.executor.make_way.ask_after = math.inf
    r0, r1 = e.robots["r0"], e.robots["r1"]
    e.apply_command(command("r0", 1, "approach", ["d_storage"], [(1.0, 5.0), (6.0, 5.0), (6.0, 4.6)]))
    while r0.phase != "done":
        assert e.time < 30.0
        e.step()
    e.apply_command(command("r0", 2, "opendoor", ["d_storage"], [], now=e.time))
    e.apply_command(command("r1", 1, "approach", ["d_storage"], [(10.0, 5.0), (6.0, 5.0), (6.0, 4.6)], now=e.time))
    events = []
    while e.time < 200.0:
        e.step()
        events += e.take_events()
    assert r0.state == "waiting_at_door" and e.executor.avoidance.kept_back("r1", e.time) > 130.0
    assert [ev for ev in events if ev.kind == "action_failed"] == []
    e.doors.human_open("d_storage", e.time)
    e.apply_command(command("r0", 3, "gothrough", ["d_storage"], [(6.0, 4.6), (6.0, 3.0)], now=e.time))
    while e.time < 260.0 and not (r0.phase == r1.phase == "done"):
        e.step()
        events += e.take_events()
    assert r0.phase == r1.phase == "done" and [ev for ev in events if ev.kind == "action_failed"] == []
    assert math.dist((r1.x, r1.y), (6.0, 4.6)) < 0.1 and e.summary()["robot_overlaps"] == 0


def test_a_wait_is_stuck_for_the_time_it_has_been_stuck_in_a_row_not_since_it_began():
    # r1 queues behind r0 (r0 makes way for a third robot: it waits for no robot); then r0 turns
    # back into r1: a cycle from that step on. r1's give-up clock starts there, not when it began
    # to queue, so r0 (which outranks it) has the time to ask it to make way.
    waits = Waits()
    robots = fleet(r0="drive", r1="drive")
    waits.on("r1", "r0")
    t = 0.0
    while t < 20.0:  # 20 s in a queue
        assert waits.stuck_for("r1", robots, t) == 0.0
        t += 0.05
    waits.on("r0", "r1")
    start = t
    while t - start < 12.0:
        assert waits.stuck_for("r1", robots, t) == t - start
        t += 0.05
    assert waits.stuck_for("r1", robots, t) >= 12.0
    t += 5.0  # not kept back for 5 s: its next wait is a new one
    assert waits.stuck_for("r1", robots, t) == 0.0


def test_a_robot_driving_around_with_nobody_in_its_way_ends_a_chain():
    waits = Waits()
    robots = fleet(r0="drive", r1="drive")
    waits.on("r1", "r0")
    waits.on("r0", "")  # r0 drives around others, kept back by no robot known: on its way
    assert waits.chain("r1") == ["r1", "r0"] and not waits.stuck("r1", robots)
    assert waits.stuck("r0", robots)  # r0 itself, kept back with nobody noted: not known to be a queue


def test_when_one_robot_of_a_cycle_gives_up_the_others_get_their_time_afresh():
    waits = Waits()
    robots = fleet(r0="drive", r1="drive")
    waits.on("r0", "r1")
    waits.on("r1", "r0")
    t = 0.0
    while t < 12.0:
        waits.stuck_for("r0", robots, t)
        waits.stuck_for("r1", robots, t)
        t += 0.05
    assert waits.stuck_for("r1", robots, t) >= 12.0
    waits.gave_up("r1")  # its action fails; the planner moves it
    robots["r1"].phase = "failed"
    assert waits.chain("r0") == ["r0", "r1"] and waits.stuck("r0", robots)  # behind a parked robot
    assert waits.stuck_for("r0", robots, t) == 0.0  # but its clock starts again


def test_time_queued_behind_a_robot_waiting_for_a_door_does_not_count_toward_patience():
    waits = Waits()
    t = 0.0
    while t < 100.0:  # 100 s in a queue behind a robot waiting for her door: not counted
        assert waits.waited("r1", t, counts=False) == 0.0
        t += 0.05
    while t < 130.0:  # the door opened; the head drives on, the queue is slow: counted from here
        counted = waits.waited("r1", t, counts=True)
        t += 0.05
    assert 29.9 < counted < 30.1
    t += 5.0  # not kept back for 5 s: its next wait is a new one
    assert waits.waited("r1", t, counts=True) == 0.0
