"""Planner before and after, in one process: every plan made by both source trees, one right after
the other, and the pair compared.

On a shared machine the load moves between runs (and within one) more than a change moves the
planner, so a change is measured against the tree before it plan by plan: both planners (the
``--before`` tree's ``services`` package loaded under another name) make the same plan one after the
other, in alternating order, under the same load; the figures to quote are the ratios of the paired
times. Every plan's content is digested too: the trees must return the same plans (a speed-up may
not pick another of several equally good plans); give time limits that do not bind
(``--time-limit 600 --solve-limit 60``) for that check, since a plan cut short by its limit depends
on the machine's speed.

    git worktree add /tmp/before HEAD
    .venv/bin/python benchmarks/planner_ab.py --before /tmp/before --robots 6,20 --seeds 2 --replans 5
    .venv/bin/python benchmarks/planner_ab.py --before /tmp/before --robots 50 --seeds 1 --replans 3 \\
        --variant threads=1

Variants: ``before`` (the tree given), ``after`` (this tree), and with ``--variant KEY=VALUE`` this
tree with that PlannerSettings field set as well (e.g. ``threads=1``: the two tie-breaking runs of a
plan from scratch one after the other). Problems: per size and seed, the first plan from the
generated site's start, then replans as ``benchmarks/planner.py`` makes them (after progress, and
after a new "door unavailable for 2 min" constraint), each variant from its own previous plan. Per
size and variant: wall and CPU seconds (median, p95), the median of the per-plan ratios to
``before``, and whether every plan equals ``before``'s; the load average before and after. Prints
one JSON document.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import importlib.util
import json
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from protocol.site import loads_site  # noqa: E402
from runtime.site.generate import generate_site  # noqa: E402

BEFORE = "before_services"  # the name the --before tree's services package is loaded under


def load_tree(tree: Path) -> None:
    """Import ``tree``'s ``services`` package as :data:`BEFORE` (its planner imports only its own
    modules, relatively, and ``protocol``, which both trees share)."""
    spec = importlib.util.spec_from_file_location(
        BEFORE, tree / "services" / "__init__.py", submodule_search_locations=[str(tree / "services")]
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[BEFORE] = module
    spec.loader.exec_module(module)


class Variant:
    """One planner: a tree's modules and the settings it plans with."""

    def __init__(self, package: str, settings: dict[str, Any]) -> None:
        self.planner_mod = importlib.import_module(f"{package}.planner.planner")
        self.constraints_mod = importlib.import_module(f"{package}.planner.constraints")
        self.world_mod = importlib.import_module(f"{package}.planner.world")
        self.settings = settings

    def planner(self, site: Any) -> Any:
        return self.planner_mod.TaskPlanner(site, self.planner_mod.PlannerSettings(**self.settings))

    def constraint(self, t: int) -> Any:
        item = self.constraints_mod.unavailable("d_storage", t, t + 120, "bench")
        return self.constraints_mod.ConstraintProgram.build([item])


def digest(result: Any) -> str:
    """The plan as the service and the CLI hand it out (times, actions, openings), without its solve time."""
    doc = result.as_json()
    doc.pop("solve_time")
    doc["uses"] = {rid: sorted(p.uses) for rid, p in sorted(result.plans.items())}
    doc["status"] = result.status
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:16]


def timed(plan: Any, *args: Any, **kwargs: Any) -> tuple[Any, float, float]:
    t0, c0 = time.perf_counter(), time.process_time()
    result = plan(*args, **kwargs)
    return result, time.perf_counter() - t0, time.process_time() - c0


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(int(round(q * (len(ordered) - 1))), len(ordered) - 1)] if ordered else float("nan")


def stats(values: list[float]) -> dict[str, float]:
    if not values:
        return {"n": 0}
    return {"n": len(values), "median": round(statistics.median(values), 4), "p95": round(percentile(values, 0.95), 4)}


def run_site(variants: dict[str, Variant], robots: int, seed: int, args: argparse.Namespace) -> list[dict]:
    """Every plan of one site, made by each variant in turn (the order alternating plan by plan)."""
    from services.planner.replay import world_at

    site = loads_site(generate_site(robots, 3, seed=seed))
    names = list(variants)
    planners = {name: v.planner(site) for name, v in variants.items()}
    rows: list[dict] = []
    turn = 0

    def each(kind: str, k: int, call: Any) -> dict[str, Any]:
        """``call(name)`` for every variant, in this turn's order: their results by name."""
        nonlocal turn
        order = names if turn % 2 == 0 else names[::-1]
        turn += 1
        results = {}
        for name in order:
            result, wall, cpu = call(name)
            results[name] = result
            rows.append(
                {"robots": robots, "seed": seed, "kind": kind, "k": k, "variant": name}
                | {"wall": wall, "cpu": cpu, "plan": digest(result)}
            )
        return results

    worlds = {name: variants[name].world_mod.initial_world(site) for name in names}
    current = each("first", 0, lambda n: timed(planners[n].plan, worlds[n], time_limit=args.first_plan_limit))
    first = current["after"]
    world = worlds["after"]
    for k in range(1, args.replans + 1):
        t = first.makespan * k / (args.replans + 1)
        world = world_at(planners["after"].builder, world, current["after"], t)
        nxt = each("replan", k, lambda n, w=world, c=current: timed(planners[n].plan, w, warm=c[n]))
        constraint = {name: v.constraint(int(t)) for name, v in variants.items()}
        each("constraint", k, lambda n, w=world, c=constraint, x=nxt: timed(planners[n].plan, w, c[n], warm=x[n]))
        current = nxt
    return rows


def summarise(rows: list[dict], names: list[str]) -> dict[str, Any]:
    def key(r: dict) -> tuple:
        return (r["seed"], r["kind"], r["k"])

    by = {name: {key(r): r for r in rows if r["variant"] == name} for name in names}
    out: dict[str, Any] = {"figures": {}, "median_ratio_to_before": {}, "same_plans_as_before": {}}
    for name in names:
        mine = list(by[name].values())
        first = [r for r in mine if r["kind"] == "first"]
        replans = [r for r in mine if r["kind"] != "first"]
        out["figures"][name] = {
            "first_plan_wall": stats([r["wall"] for r in first]),
            "first_plan_cpu": stats([r["cpu"] for r in first]),
            "replan_wall": stats([r["wall"] for r in replans]),
            "replan_cpu": stats([r["cpu"] for r in replans]),
        }
        if name == "before":
            continue
        ratios: dict[str, float] = {}
        for label, kinds in (("first_plan", ("first",)), ("replan", ("replan", "constraint"))):
            for measure in ("wall", "cpu"):
                paired = [
                    r[measure] / by["before"][k][measure]
                    for k, r in by[name].items()
                    if k[1] in kinds and by["before"][k][measure] > 0
                ]
                if paired:
                    ratios[f"{label}_{measure}"] = round(statistics.median(paired), 3)
        out["median_ratio_to_before"][name] = ratios
        out["same_plans_as_before"][name] = all(by["before"][k]["plan"] == r["plan"] for k, r in by[name].items())
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--before", required=True, help="the tree to compare with (git worktree add /tmp/before HEAD)")
    parser.add_argument("--variant", action="append", default=[], help="KEY=VALUE: this tree with that setting too")
    parser.add_argument("--robots", default="6,20", help="team sizes, comma-separated")
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--replans", type=int, default=5)
    parser.add_argument("--time-limit", type=float, default=5.0, help="s for one IIDP plan (the service's)")
    parser.add_argument("--solve-limit", type=float, default=2.0, help="s for one clingo call (the service's)")
    parser.add_argument("--first-plan-limit", type=float, default=60.0)
    args = parser.parse_args()
    load_tree(Path(args.before).resolve())
    base = {"time_limit": args.time_limit, "solve_limit": args.solve_limit}
    variants = {"before": Variant(BEFORE, base), "after": Variant("services", base)}
    for kv in args.variant:
        field, value = kv.split("=", 1)
        variants[f"after_{kv}"] = Variant("services", base | {field: int(value)})
    load_start = round(os.getloadavg()[0], 2)
    report: dict[str, Any] = {
        "benchmark": "planner_ab",
        "command": " ".join([Path(sys.executable).name, "benchmarks/planner_ab.py", *sys.argv[1:]]),
        "sizes": {},
    }
    for robots in [int(x) for x in args.robots.split(",") if x]:
        rows: list[dict] = []
        for seed in range(args.seeds):
            rows += run_site(variants, robots, seed, args)
        report["sizes"][str(robots)] = summarise(rows, list(variants))
        print(f"[planner_ab] {robots} robots done", file=sys.stderr, flush=True)
    report["machine"] = {
        "cpus": os.cpu_count(),
        "load_avg_1min_at_start": load_start,
        "load_avg_1min_at_end": round(os.getloadavg()[0], 2),
    }
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
