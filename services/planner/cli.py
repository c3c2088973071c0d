"""Command line of the planner: ``arroch planner`` (the service) and ``arroch plan`` (one plan, printed).

Exit codes of ``arroch plan``: 0 a plan was found; 1 no plan (constraints conflict, or a robot
cannot do its tasks; the reason goes to stderr); 2 bad usage or configuration.
"""

from __future__ import annotations

import argparse
import json
import sys

from runtime.runner import add_common_arguments, run_service
from runtime.transport import options_from

EXIT_NO_PLAN = 1
EXIT_CONFIG = 2


def register(subparsers: argparse._SubParsersAction) -> None:
    svc = subparsers.add_parser(
        "planner",
        help="run the task planner service (IIDP over clingo, motion planning, dispatch)",
        description="The planner service: plans for every robot from poses, statuses, door states and the active "
        "constraints; publishes the TeamPlan, each robot's RobotCommand and Intent; replans on events.",
    )
    add_common_arguments(svc)
    _planning_arguments(svc, default_limit=5.0)
    svc.add_argument(
        "--off-track",
        type=float,
        default=1.0,
        metavar="M",
        help="distance from the trajectory that triggers a replan (default 1.0 m)",
    )
    svc.add_argument(
        "--collision-free",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="time each robot's trajectory against the others' (space-time reservations): robots wait or pull "
        "aside (default off: on generated 6-robot sites it meets more and can stall the task planner; "
        "see docs/services/planner.md)",
    )
    svc.set_defaults(func=_run_service)

    one = subparsers.add_parser(
        "plan",
        help="compute one plan for a site's start and print it",
        description="Plan once for the site's initial state (every robot at its start, nothing delivered) "
        "and print the plan.",
    )
    one.add_argument(
        "--site", "--config", dest="site", metavar="FILE", help="site file (TOML); default: the packaged 'office' site"
    )
    add_common_arguments(one, site=False, zenoh=False)
    _planning_arguments(one, default_limit=30.0)
    one.add_argument(
        "--unavailable",
        action="append",
        default=[],
        metavar="DOOR:T0:T1",
        help="the human will not open DOOR in [T0, T1) (integer seconds); repeatable",
    )
    one.add_argument(
        "--constraints",
        action="append",
        default=[],
        metavar="FILE.lp",
        help="extra constraints in the shared ASP vocabulary (docs/architecture.md); repeatable",
    )
    one.add_argument(
        "--start-time", type=int, default=0, metavar="T", help="site-clock second the plan starts at (default 0)"
    )
    one.add_argument("--json", action="store_true", help="print the plan as JSON")
    one.set_defaults(func=_run_plan)


def _planning_arguments(parser: argparse.ArgumentParser, *, default_limit: float) -> None:
    parser.add_argument(
        "--method", choices=("iidp", "joint"), default="iidp", help="IIDP (default) or the joint program (small teams)"
    )
    parser.add_argument(
        "--time-limit",
        type=float,
        default=default_limit,
        metavar="S",
        help=f"solver time for one plan (default {default_limit:g} s); past it the best plan so far is used",
    )
    parser.add_argument(
        "--solve-limit",
        type=float,
        default=2.0,
        metavar="S",
        help="solver time for one robot's program inside IIDP (default 2 s; 5x that for the rare larger programs)",
    )
    parser.add_argument(
        "--routes",
        type=int,
        default=1,
        metavar="K",
        help="candidate routes per leg (default 1; 2 when constraints mention rooms)",
    )


def _settings(args: argparse.Namespace):
    from .planner import PlannerSettings

    if args.time_limit <= 0:
        raise ValueError("--time-limit must be positive")
    if args.solve_limit <= 0:
        raise ValueError("--solve-limit must be positive")
    if args.routes < 1:
        raise ValueError("--routes must be at least 1")
    return PlannerSettings(
        time_limit=args.time_limit,
        solve_limit=args.solve_limit,
        joint_time_limit=args.time_limit,
        routes_per_leg=args.routes,
    )


def _run_service(args: argparse.Namespace) -> int:
    from protocol.site import load_site
    from runtime.clock import make_clock

    from .service import PlannerService
    from .settings import ServiceSettings

    def build() -> PlannerService:
        site = load_site(args.site)
        if args.off_track <= 0:
            raise ValueError("--off-track must be positive")
        settings = ServiceSettings(
            method=args.method, planner=_settings(args), off_track=args.off_track, collision_free=args.collision_free
        )
        return PlannerService(
            site, args.namespace or site.name, options_from(args), clock=make_clock(args.clock), settings=settings
        )

    return run_service(build)


def _run_plan(args: argparse.Namespace) -> int:
    from protocol.site import load_site

    from . import constraints as C
    from .planner import TaskPlanner
    from .world import initial_world

    try:
        site = load_site(args.site)
        settings = _settings(args)
        items = [C.parse_unavailable(spec, i) for i, spec in enumerate(args.unavailable, start=1)]
        items += [C.from_file(path) for path in args.constraints]
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    program = C.ConstraintProgram.build(items) if items else None
    if program is not None and program.invalid:
        for cid, why in sorted(program.invalid.items()):
            print(f"error: constraint {cid}: {why}", file=sys.stderr)
        return EXIT_CONFIG
    result = TaskPlanner(site, settings).plan(initial_world(site, now=float(args.start_time)), program, args.method)
    if result.status not in ("ok", "timeout"):
        print(f"no plan: {result.diagnostic}", file=sys.stderr)
        if result.conflict_ids:
            print(f"conflicting constraints: {', '.join(result.conflict_ids)}", file=sys.stderr)
        return EXIT_NO_PLAN
    if args.json:
        print(json.dumps(result.as_json(), indent=2))
        return 0
    print(
        f"{result.method}: makespan {result.makespan} s, {result.door_openings} door openings, "
        f"{result.iterations} rounds, {result.solve_time:.2f} "
        f"s{' (time limit hit)' if result.status == 'timeout' else ''}"
    )
    for o in result.openings:
        print(f"  human opens {o.door} at {result.absolute(o.start)} for {', '.join(o.robots)}")
    for rid, plan in sorted(result.plans.items()):
        print(f"{rid} (done at {result.absolute(plan.finish)}):")
        for s in plan.steps:
            print(f"  {result.absolute(s.start):6d} {result.absolute(s.end):6d}  {s.action}({', '.join(s.args)})")
    return 0
