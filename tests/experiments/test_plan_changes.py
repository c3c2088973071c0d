"""How feedback changed the plans of a trial, from constructed TeamPlans and sim events."""

from __future__ import annotations

from types import SimpleNamespace as S

from services.experiments.plan_changes import PlanRecord, door_wait, plan_changes, reordered, replans

STORAGE = ("approach", "d_storage"), ("opendoor", "d_storage"), ("gothrough", "d_storage")


def steps(*actions: tuple[str, str]) -> list[S]:
    return [S(action=a, args=[x], start=0.0, end=0.0) for a, x in actions]


def plan(plan_id: int, world: int, constraints: int, **robots: list[S]) -> PlanRecord:
    return PlanRecord.of(S(plan_id=plan_id, world_version=world, constraints_version=constraints, robots=robots))


STORE_FIRST = steps(("load", "o1"), *STORAGE, ("unload", "o1"), ("load", "o2"), ("unload", "o2"))
OFFICE_FIRST = steps(("load", "o2"), ("unload", "o2"), ("load", "o1"), *STORAGE, ("unload", "o1"))


def test_a_constraint_that_reorders_a_robot_is_counted_once_per_robot() -> None:
    plans = [
        plan(1, 1, 0, r0=STORE_FIRST, r1=STORE_FIRST),
        plan(2, 2, 0, r0=STORE_FIRST, r1=STORE_FIRST),  # world 2, before the feedback
        plan(3, 2, 1, r0=OFFICE_FIRST, r1=STORE_FIRST),  # the constraint: r0 reorders, r1 keeps its order
        plan(4, 3, 1, r0=OFFICE_FIRST[1:], r1=STORE_FIRST),
    ]
    ((old, new),) = replans(plans)
    assert (old.plan_id, new.plan_id) == (2, 3)
    assert reordered(old, new) == 1
    changes = plan_changes(plans, [], ["d_storage"])
    assert (changes.constraint_replans, changes.plans_changed, changes.deliveries_reordered) == (1, 1, 1)
    assert changes.spanning == 0


def test_a_constraint_that_only_retimes_changes_no_plan_and_the_last_plan_of_a_version_counts() -> None:
    plans = [
        plan(1, 4, 0, r0=STORE_FIRST),
        plan(2, 4, 0, r0=OFFICE_FIRST),  # republished for the same version: this one is the plan replaced
        plan(3, 4, 1, r0=OFFICE_FIRST),
        plan(5, 6, 2, r0=[]),
        plan(4, 5, 1, r0=OFFICE_FIRST[2:]),
    ]
    changes = plan_changes(plans, [], ["d_storage"])
    assert (changes.constraint_replans, changes.plans_changed, changes.deliveries_reordered) == (2, 1, 0)
    assert changes.spanning == 1  # constraints 2 came with world 6, the plan replaced was world 5's


def test_no_feedback_means_no_constraint_replans() -> None:
    plans = [plan(i, i, 0, r0=STORE_FIRST) for i in range(1, 5)]
    assert plan_changes(plans, [], ["d_storage"]).as_dict()["constraint_replans"] == 0


def event(t: float, kind: str, robot: str = "", door: str = "", **data: object) -> dict[str, object]:
    return {"time": t, "kind": kind, "robot": robot, "door": door, "data": data}


def test_door_wait_runs_from_waiting_at_her_door_to_the_door_opening() -> None:
    events = [
        event(10.0, "waiting_at_door", "r0", "d_storage", action="opendoor", action_id=3),
        event(12.0, "waiting_at_door", "r1", "d_storage", action="opendoor", action_id=5),
        event(15.0, "waiting_at_door", "r2", "d_lab", action="opendoor", action_id=2),  # not her door
        event(20.0, "door_opened", door="d_storage"),  # ends r0's (10 s) and r1's (8 s)
        event(30.0, "waiting_at_door", "r0", "d_storage", action="gothrough", action_id=4),  # held, not an opendoor
        event(40.0, "waiting_at_door", "r1", "d_storage", action="opendoor", action_id=7),
        event(44.5, "action_failed", "r1", action_id=7),  # 4.5 s
        event(50.0, "waiting_at_door", "r0", "d_storage", action="opendoor", action_id=9),
        event(53.0, "mission_done"),  # 3 s
    ]
    assert door_wait(events, ["d_storage"]) == 10.0 + 8.0 + 4.5 + 3.0
