"""The traffic rules' shared tables, between robot processes: ``RobotTraffic``.

The rules that keep robots apart share state between robots: whom each robot stops for (the right
of way's ``blocked_by``, whose cycles decide who goes on), whom it waits for (``Waits``: a queue or
a cycle), who asks for and holds each doorway (``Doorways``), and who asked whom to make way
(``MakeWay``). In the simulator one executor steps every robot and these tables are plain
dictionaries. Each ``arroch robot`` process steps only its own robot: it owns that robot's rows
(what *it* stops for, waits for, asks for, holds, and the requests it made), publishes them as a
``RobotTraffic`` (:func:`traffic_of`) on every change and once a second, and, before each step,
takes the other robots' latest rows into its executor's tables (:func:`adopt`), or drops them for
a robot it has not heard of for a while (:func:`forget`). So every process follows the same chains
and ranks, a control period or two late.

What cannot be decided by one process alone is settled the same way in each: two robots that both
took a doorway before hearing of each other keep the claim :func:`runtime.executor.doorways._claim`
orders first (the other gives it up and asks again); a robot asked to make way by two robots at once
answers the one that asked first (:meth:`MakeWay.adopt`). A request to make way is ended by the
robot asked as it answers it and by its asker as it prunes its own (:meth:`MakeWay.prune`), by the
same test.
"""

from __future__ import annotations

from protocol.messages import DoorwayHold, MakeWayAsk, RobotTraffic
from protocol.site.model import Site

from .doorways import DoorwayRows, Hold
from .executor import RobotExecutor
from .make_way import Request


def traffic_of(executor: RobotExecutor, robot: str) -> RobotTraffic:
    """``robot``'s own rows of the executor's tables."""
    rows = executor.doorways.rows(robot)
    asking, asked_at = rows.asking or ("", 0.0)
    return RobotTraffic(
        robot=robot,
        blocked_by=executor.right_of_way.blocked_by.get(robot, ""),
        waits_for=executor.waits.waits_for.get(robot, ""),
        crossing=rows.crossing,
        asking=asking,
        asked_at=asked_at,
        holds=[DoorwayHold(opening=h.opening, at=list(h.at), entered=h.entered) for h in rows.holds],
        asks=[
            MakeWayAsk(asked=asked, way=[list(p) for p in r.way], since=r.since, renewed=r.renewed, root=r.root)
            for asked, r in sorted(executor.make_way.made_by(robot).items())
        ],
    )


def adopt(executor: RobotExecutor, traffic: RobotTraffic, now: float) -> None:
    """Take ``traffic`` as its robot's rows now (a robot another process steps)."""
    rid = traffic.robot
    for table, other in (
        (executor.right_of_way.blocked_by, traffic.blocked_by),
        (executor.waits.waits_for, traffic.waits_for),
    ):
        if other:
            table[rid] = other
        else:
            table.pop(rid, None)
    executor.doorways.adopt(
        rid,
        DoorwayRows(
            traffic.crossing,
            (traffic.asking, traffic.asked_at) if traffic.asking else None,
            tuple(Hold(h.opening, (h.at[0], h.at[1]), h.entered) for h in traffic.holds),
        ),
    )
    made = {a.asked: Request(rid, [(p[0], p[1]) for p in a.way], a.since, a.renewed, a.root) for a in traffic.asks}
    executor.make_way.adopt(rid, made, now)


def forget(executor: RobotExecutor, robot: str) -> None:
    """Drop ``robot``'s rows (it has not been heard of for a while: it waits for nothing, asks nothing)."""
    executor.right_of_way.blocked_by.pop(robot, None)
    executor.waits.waits_for.pop(robot, None)
    executor.doorways.adopt(robot, DoorwayRows())
    executor.make_way.adopt(robot, {}, 0.0)


def traffic_problem(traffic: RobotTraffic, site: Site) -> str:
    """Why ``traffic`` cannot be taken (a robot or opening the site does not have), naming the
    field; "" when it can."""
    robots = site.robots
    for name in ("robot", "blocked_by", "waits_for"):
        rid = getattr(traffic, name)
        if rid and rid not in robots:
            return f"{name}: no robot {rid!r} on site {site.name}"
    for name in ("crossing", "asking"):
        oid = getattr(traffic, name)
        if oid and oid not in site.openings:
            return f"{name}: no door or passage {oid!r} on site {site.name}"
    for i, hold in enumerate(traffic.holds):
        if hold.opening not in site.openings:
            return f"holds[{i}].opening: no door or passage {hold.opening!r} on site {site.name}"
    for i, ask in enumerate(traffic.asks):
        for name in ("asked", "root"):
            rid = getattr(ask, name)
            if (rid or name == "asked") and rid not in robots:
                return f"asks[{i}].{name}: no robot {rid!r} on site {site.name}"
    return ""
