"""Collision-free team motion: a robot timed against another's committed trajectory never touches
it - head-on in a corridor (it pulls aside) and at a door (it waits) - and the waits are in the
timing: the trajectory's timestamps and the plan's step times move together."""

from __future__ import annotations

import numpy as np
import pytest

from runtime.pursuit import Path
from services.planner.motion import MotionPlanner
from services.planner.plan import Pass, RobotPlan, Step
from services.planner.reservations import ReservationTable
from services.planner.teammotion import TeamMotion, delay_plan
from services.planner.world import RobotState, World
from tests.sim.helpers import small_site

# small_site: a corridor y in [4, 6] (2 m wide, x 0..12), an office above it (x 0..6) behind d_office
# at (3, 6), 0.9 m wide.

# The table checks every 0.2 s: between two checks robots may come a few mm inside the 0.05 m margin
# (never inside the discs).
SLACK = 0.01


def least_distance(a: list[list[float]], b: list[list[float]], step: float = 0.05) -> float:
    """Least distance between two robots following rows ``a`` and ``b`` (each standing at its ends
    before and after), checked every ``step`` seconds over both."""
    ta, tb = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    times = np.arange(min(ta[0, 0], tb[0, 0]), max(ta[-1, 0], tb[-1, 0]) + 5.0, step)

    def at(rows: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(times, rows[:, 0], rows[:, 1]), np.interp(times, rows[:, 0], rows[:, 2])], axis=-1)

    return float(np.linalg.norm(at(ta) - at(tb), axis=-1).min())


@pytest.fixture(scope="module")
def motion() -> MotionPlanner:
    return MotionPlanner(small_site())


def world(poses: dict[str, tuple[float, float, float]], now: float = 0.0) -> World:
    return World(now=now, robots={rid: RobotState(id=rid, pose=pose) for rid, pose in poses.items()})


def plain(motion: MotionPlanner, a: tuple[float, float], b: tuple[float, float], t0: float) -> list[list[float]]:
    return motion.trajectory(motion.path(a, b).points, t0)


def test_head_on_in_a_corridor_the_later_robot_pulls_aside(motion):
    r = motion.site.params.robot_radius
    first = plain(motion, (1.0, 5.0), (11.0, 5.0), 0.0)  # r0 drives the corridor's centre line east
    second = plain(motion, (9.0, 5.0), (2.0, 5.0), 0.0)  # r1 comes west along the same line
    assert least_distance(first, second) < 2 * r  # as planned alone, they collide
    team = TeamMotion(motion)
    team.begin(world({"r0": (1.0, 5.0, 0.0), "r1": (9.0, 5.0, np.pi)}), {"r0": first})
    timed = team.timed("r1", second, 0.0, not_before=None, planned_end=second[-1][0])
    assert least_distance(first, timed) >= 2 * r + team.table.margin - SLACK
    # it left the centre line (a safe spot) and still ends where it was going
    assert max(abs(row[2] - 5.0) for row in timed) >= 2 * r
    assert timed[-1][1:3] == pytest.approx([2.0, 5.0], abs=1e-6)
    assert team.delays["r1"] == int(np.ceil(timed[-1][0] - second[-1][0] - 1e-6)) > 0


def test_at_a_door_the_later_robot_waits_its_turn_and_the_wait_is_in_the_timing(motion):
    r = motion.site.params.robot_radius
    # r0 goes from the corridor up through d_office into the office; r1 comes down from the office
    # through the same door into the corridor at the same time.
    first = plain(motion, (3.0, 4.8), (4.5, 8.5), 0.0)
    second = plain(motion, (2.0, 7.6), (5.0, 4.8), 0.0)
    assert least_distance(first, second) < 2 * r
    team = TeamMotion(motion)
    team.begin(world({"r0": (3.0, 4.8, np.pi / 2), "r1": (2.0, 7.6, -np.pi / 2)}), {"r0": first})
    timed = team.timed("r1", second, 0.0, not_before=None, planned_end=second[-1][0])
    assert least_distance(first, timed) >= 2 * r + team.table.margin - SLACK
    # the wait is a hold (two rows at one point) the controller keeps, and it makes r1 later
    path = Path(timed)
    assert path.holds and path.hold_limit(0.0) < path.length
    assert timed[-1][0] > second[-1][0]
    # ... by as much as the plan is moved: its step times and the trajectory's agree
    delay = team.delays["r1"]
    plan = RobotPlan(
        "r1",
        (Step("gothrough", ("d_office",), 0, int(second[-1][0]) + 1), Step("load", ("o0",), 20, 30)),
        finish=30,
        passes=(Pass("d_office", 0, int(second[-1][0]) + 1, "office", "corridor", False),),
    )
    moved = delay_plan(plan, 0, delay)
    assert moved.steps[0].end == plan.steps[0].end + delay >= timed[-1][0]
    assert moved.steps[1].start == 20 + delay and moved.finish == 30 + delay
    assert moved.passes[0].end == plan.passes[0].end + delay


def test_a_gothrough_is_held_until_its_planned_start(motion):
    team = TeamMotion(motion)
    team.begin(world({"r0": (3.0, 4.8, np.pi / 2)}), {})
    rows = plain(motion, (3.0, 4.8), (3.0, 6.8), 10.0)
    timed = team.timed("r0", rows, 10.0, not_before=14.0, planned_end=None)
    assert timed[0][0] == 10.0 and timed[1][0] == 14.0 and timed[0][1:3] == timed[1][1:3]
    assert Path(timed).hold_limit(12.0) == 0.0 and Path(timed).hold_limit(14.5) == np.inf


def test_the_table_finds_the_first_conflict():
    table = ReservationTable(radius=0.25)
    table.reserve("a", [[0.0, 0.0, 0.0, 0.0], [10.0, 5.0, 0.0, 0.0]])
    assert table.first_conflict("b", [[0.0, 5.0, 2.0, 0.0]]) is None
    t, who = table.first_conflict("b", [[0.0, 5.0, 0.3, 0.0]])
    assert who == "a" and 8.5 < t < 10.0  # a comes within 0.55 m of (5, 0.3) shortly before 10 s
