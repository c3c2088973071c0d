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
    # to fail - and gets there once r0 has gone through.
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
    while e.time < 90.0:
        e.step()
        events += e.take_events()
    assert r0.state == "waiting_at_door" and e.executor.avoidance.kept_back("r1", e.time) > 30.0
    assert [ev for ev in events if ev.kind == "action_failed"] == []
    e.doors.human_open("d_storage", e.time)
    e.apply_command(command("r0", 3, "gothrough", ["d_storage"], [(6.0, 4.6), (6.0, 3.0)], now=e.time))
    while e.time < 150.0 and not (r0.phase == r1.phase == "done"):
        e.step()
        events += e.take_events()
    assert r0.phase == r1.phase == "done" and [ev for ev in events if ev.kind == "action_failed"] == []
    assert math.dist((r1.x, r1.y), (6.0, 4.6)) < 0.1 and e.summary()["robot_overlaps"] == 0
