"""Peers side by side: the delivery problems solved by the temporal planners a robotics user would
pick (through ``unified-planning``: TAMER, Aries, LPG, ENHSP), against IIDP and the joint program.

Problems: the packaged office site (the paper's building; its first 2 and all 3 robots) and
generated sites (``runtime.site.generate.generate_site``, seed ``--seed``) with ``--robots`` robots, each
with ``--objects`` objects per robot; every one without and with a window in which the human opens
no door (``--window``, on the storage door). Each is planned by IIDP and, up to
``--joint-max-robots`` robots, the joint program (both with ``--time-limit``), and encoded for
``unified-planning`` (``benchmarks/lib/up_delivery.py``; ``benchmarks/peers.md`` explains the
encoding) and solved by each engine that is installed, in the encodings it takes:

- ``tamer/temporal``, ``aries/temporal``: durative actions, openings shared, the window as timed
  initial literals;
- ``lpg/temporal`` (LPG has no required concurrency, so it is expected to find no plan: measured,
  not assumed) and ``lpg/unshared`` (a pass through the human's door as one action, no sharing;
  LPG takes no timed initial literals, so no window);
- ``enhsp/clock`` (ENHSP takes no durative actions: robots' clocks as numeric fluents).

Each solver but IIDP runs in a process of its own, stopped at ``--time-limit`` seconds (plus
``GRACE`` for a JVM or a server to start); a time-out is reported as such, with the wall and (at
least) CPU seconds it had. Every plan is checked by unified-planning's ``PlanValidator`` against its
problem and by the project's validator (``services.planner.validator.validate``) against the site;
a makespan ratio to IIDP (the slowest robot's finishing time over IIDP's) is given only for a plan
both accept. Calibration problems first (``--calibration``: 1 robot with 1 and 3 objects, 2 robots
with 1, no window) show that every engine can solve the encodings it is given and where it stops.
An engine is not run (and says why) on a problem at least as hard as one it found no valid plan
for - as many robots, objects per robot and constraints, on the same kind of site - nor anywhere
after it reported no plan (not a time-out) for a calibration problem; ``--run-all`` runs it anyway.

Prints one JSON document and writes it to ``--out`` with a plot (``--plot``).

    .venv/bin/python benchmarks/peers.py                      # the full set (about 30 minutes)
    .venv/bin/python benchmarks/peers.py --robots 2 --objects 1 --office 0 --joint-max-robots 0
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import platform
import re
import resource
import signal
import sys
import time
import traceback
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from importlib import metadata
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.lib.figures import log  # noqa: E402
from protocol.site import Site, loads_site  # noqa: E402
from protocol.site.load import parse_toml, read_text  # noqa: E402
from runtime.site.generate import generate_site  # noqa: E402
from runtime.site.tomlw import dump_site  # noqa: E402
from services.planner.constraints import ConstraintProgram, unavailable  # noqa: E402
from services.planner.planner import PlannerSettings, TaskPlanner  # noqa: E402
from services.planner.validator import Windows, validate, validate_result  # noqa: E402
from services.planner.world import World, initial_world  # noqa: E402

try:
    import unified_planning  # noqa: F401
except ImportError:  # the `peers` extra is not installed
    unified_planning = None

# (engine, encoding): every engine in the encodings it can take (benchmarks/lib/up_delivery.py)
RUNS = (("tamer", "temporal"), ("aries", "temporal"), ("lpg", "temporal"), ("lpg", "unshared"), ("enhsp", "clock"))
ENGINE_PARAMS: dict[str, dict[str, Any]] = {"lpg": {"-seed": 1}}  # LPG draws a random seed otherwise
BOUNDED_INTS = {"aries"}  # Aries takes only bounded integers; LPG and ENHSP take no bounded types
CALIBRATION = [(1, 1), (2, 1), (1, 3)]  # robots x objects each, smallest first
GRACE = 5.0  # s past the time limit before an engine's process is stopped (a JVM or server starting)
SAMPLE_EVERY = 0.25  # s between looks at a solver's processes (their CPU time)
PEER_PACKAGES = ("unified-planning", "up-tamer", "up-aries", "up-lpg", "up-enhsp", "clingo")
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "peers.json"
DEFAULT_PLOT = ROOT / "benchmarks" / "results" / "peers.png"


@dataclass(frozen=True)
class Instance:
    site_kind: str  # "office" | "generated" | "calibration" (a generated site)
    robots: int
    objects: int
    window: tuple[str, int, int] | None
    site: Site

    @property
    def label(self) -> str:
        window = " with window" if self.window else ""
        return f"{self.site_kind} {self.robots} robots x {self.objects // self.robots} objects{window}"

    def harder_than(self, other: Instance) -> bool:
        """At least as many robots, objects per robot and constraints as ``other``, on the same kind
        of site: an engine that found no plan for ``other`` is not run on this one."""
        return (
            other.site_kind == self.site_kind
            and self.robots >= other.robots
            and self.objects // self.robots >= other.objects // other.robots
            and (self.window is not None or other.window is None)
        )


# ---------------------------------------------------------------------- problems


def office(robots: int) -> Site:
    """The packaged office site with its first ``robots`` robots and their objects."""
    text, file, _ = read_text(None)
    doc = parse_toml(text, file)
    keep = {r["id"] for r in doc["robots"][:robots]}
    if len(keep) < robots:
        raise ValueError(f"the office site has {len(keep)} robots, not {robots}")
    doc["robots"] = [r for r in doc["robots"] if r["id"] in keep]
    doc["objects"] = [o for o in doc["objects"] if o["robot"] in keep]
    return loads_site(dump_site(doc), f"office_{robots}")


def instances(args: argparse.Namespace) -> list[Instance]:
    windows = [None, ("d_storage", *args.window)]
    out: list[Instance] = []
    for window in windows:
        for n in args.office:
            site = office(n)
            out.append(Instance("office", n, len(site.objects), window, site))
        for n in args.robots:
            site = loads_site(generate_site(n, args.objects, seed=args.seed))
            out.append(Instance("generated", n, len(site.objects), window, site))
    return out


# ---------------------------------------------------------------------- solving apart, with a hard time limit


def _cpu_seconds() -> float:
    """CPU seconds of this process and the children it has waited for (an engine's binary)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def process_tree(root: int) -> dict[int, tuple[int, float]]:
    """``root`` and every process descended from it (from /proc): pid -> (process group, its own CPU
    seconds). unified-planning starts PDDL planners in sessions of their own, so a process group
    alone does not hold them."""
    tick = os.sysconf("SC_CLK_TCK")
    procs: dict[int, tuple[int, int, float]] = {}  # pid -> ppid, pgrp, cpu
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # it ended meanwhile
        # after the name: state, ppid, pgrp, ...; utime and stime at 11 and 12
        procs[int(stat.parent.name)] = (int(fields[1]), int(fields[2]), (int(fields[11]) + int(fields[12])) / tick)
    tree, frontier = {}, [root]
    while frontier:
        pid = frontier.pop()
        if pid in procs and pid not in tree:
            tree[pid] = procs[pid][1:]
            frontier += [p for p, (ppid, _, _) in procs.items() if ppid == pid]
    return tree


def stop_tree(root: int) -> None:
    """Stop ``root`` (a solver's process, leader of its own group) and everything it started, each
    by its id."""
    try:
        os.killpg(root, signal.SIGSTOP)  # nothing new starts while the tree is read
    except ProcessLookupError:
        return
    for pid, (group, _) in process_tree(root).items():
        try:
            if group == pid:  # a group it started (its own, or an engine's session): all of it
                os.killpg(group, signal.SIGKILL)
            else:
                os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def _child(work: Callable[[], dict], conn: Connection) -> None:
    os.setsid()  # a process group of its own: what it starts (LPG, Java, Aries' server) is stopped with it
    os.dup2(2, 1)  # stdout carries the JSON document: whatever a solver prints goes to stderr
    warnings.simplefilter("ignore")
    try:
        t0, c0 = time.perf_counter(), _cpu_seconds()
        out = work()
        out.setdefault("seconds", time.perf_counter() - t0)
        out.setdefault("cpu_seconds", _cpu_seconds() - c0)
    except Exception as exc:  # a solver's failure is a result, reported as such
        out = {"status": "error", "error": f"{type(exc).__name__}: {exc}"[:500], "trace": traceback.format_exc()}
    conn.send(out)
    conn.close()


def run_apart(work: Callable[[], dict], limit: float) -> dict:
    """``work()`` in a process of its own (and its process group), stopped after ``limit`` seconds
    (plus GRACE): solvers differ in whether and how they honour a time limit (TAMER takes none, the
    joint program's grounding is not bounded by its solve limit). Its dict comes back with
    ``seconds`` and ``cpu_seconds``; a result after ``limit`` is a time-out."""
    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(work, send), daemon=True)
    t0 = time.perf_counter()
    proc.start()
    send.close()
    seen: dict[int, float] = {}  # pid -> its CPU seconds when last seen: engines nobody waits for count too
    try:
        while not receive.poll(SAMPLE_EVERY):
            for pid, (_, cpu) in process_tree(proc.pid).items():
                seen[pid] = max(seen.get(pid, 0.0), cpu)
            if time.perf_counter() - t0 > limit + GRACE:
                out: dict = {"status": "timeout"}
                break
        else:
            try:
                out = receive.recv()
            except EOFError:
                out = {"status": "error", "error": f"the solver's process ended (exit code {proc.exitcode})"}
    finally:
        stop_tree(proc.pid)  # on a time-out; otherwise whatever it left behind (nothing, normally)
        proc.join()
        receive.close()
    # at least this much CPU: the process and the children it waited for, or every process seen
    out["cpu_seconds"] = max(out.get("cpu_seconds", 0.0), sum(seen.values()))
    out.setdefault("seconds", time.perf_counter() - t0)
    if out["seconds"] > limit + GRACE and out.get("status") != "error":
        out["status"] = "timeout"  # an answer past the limit does not count
    return out


# ---------------------------------------------------------------------- IIDP and the joint program


def run_asp(inst: Instance, planner: TaskPlanner, world: World, method: str, limit: float) -> dict:
    """IIDP (here) or the joint program (apart, stopped at ``limit``) on ``inst``: makespan, openings,
    seconds, and the validator's verdict."""
    constraints = windows = None
    if inst.window:
        item = unavailable(*inst.window, "window")
        constraints = ConstraintProgram.build([item])
        windows = Windows.of(constraints.facts())
    if method == "iidp":
        t0, c0 = time.perf_counter(), time.process_time()
        result = planner.plan(world, constraints, time_limit=limit)
        out = {"result": result, "seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0}
    else:
        out = run_apart(lambda: {"result": planner.plan(world, constraints, method)}, limit)
    result = out.get("result")
    row: dict[str, Any] = {"status": out.get("status", result.status if result else "error")}
    row.update(seconds=round(out["seconds"], 3), cpu_seconds=_rounded(out.get("cpu_seconds")))
    if result is None or row["status"] == "timeout":
        row.update({k: out[k] for k in ("error",) if k in out})
        return row
    if method == "joint" and "IIDP's plan kept" in result.diagnostic:
        # planner.plan keeps IIDP's plan (and says so) when the joint program found none in time
        row.update(status="timeout", detail=result.diagnostic)
        return row
    errors = validate_result(inst.site, world, result, windows) if result.plans else ["no plan"]
    row.update(
        makespan=result.makespan if result.plans else None,
        door_openings=result.door_openings,
        valid=not errors,
        errors=errors[:5],
    )
    if method == "joint":
        row["optimal"] = result.optimal
    return row


def _rounded(x: float | None) -> float | None:
    return round(x, 3) if x is not None else None


# ---------------------------------------------------------------------- the engines


def fix_lpg_plan_reader() -> None:
    """up-lpg 0.1.3 cannot read its own binary's plans: each line ends ``[5.0000])`` (a stray ``)``)
    and its pattern wants ``[5.0000]``. Drop the stray bracket before it reads the file."""
    from up_lpg import lpg_planner

    original = lpg_planner.LPGEngine._plan_from_file
    if getattr(original, "fixed", False):
        return

    def read(self, problem, plan_filename, get_item_named):
        path = Path(plan_filename)
        path.write_text(re.sub(r"\]\)[ \t]*$", "]", path.read_text(), flags=re.M))
        return original(self, problem, plan_filename, get_item_named)

    read.fixed = True  # type: ignore[attr-defined]
    lpg_planner.LPGEngine._plan_from_file = read


def solve_with(problem, engine: str, limit: float) -> dict:
    """In the engine's process: solve, and return the plan as plain data (names and times)."""
    from unified_planning.plans import TimeTriggeredPlan
    from unified_planning.shortcuts import OneshotPlanner, get_environment

    get_environment().credits_stream = None
    fix_lpg_plan_reader()
    with OneshotPlanner(name=engine, params=ENGINE_PARAMS.get(engine, {})) as planner:
        result = planner.solve(problem, timeout=limit)
    plan = None
    if result.plan is not None:
        if isinstance(result.plan, TimeTriggeredPlan):
            items = [(str(s), a, str(d)) for s, a, d in result.plan.timed_actions]
        else:
            items = [(None, a, None) for a in result.plan.actions]
        plan = [(s, a.action.name, [str(p) for p in a.actual_parameters], d) for s, a, d in items]
    messages = [m.message.strip()[-300:] for m in result.log_messages or [] if m.message.strip()]
    return {"status": result.status.name.lower(), "plan": plan, "log": messages[-1:]}


def rebuild_plan(problem, items: list) -> Any:
    """The plan an engine's process sent, as a unified-planning plan of ``problem``."""
    from unified_planning.plans import ActionInstance, SequentialPlan, TimeTriggeredPlan

    def instance(name: str, params: list[str]) -> ActionInstance:
        return ActionInstance(problem.action(name), tuple(problem.object(p) for p in params))

    if items and items[0][0] is not None:
        return TimeTriggeredPlan([(Fraction(s), instance(n, p), Fraction(d)) for s, n, p, d in items])
    return SequentialPlan([instance(n, p) for _, n, p, _ in items])


def run_peer(
    inst: Instance, planner: TaskPlanner, world: World, engine: str, kind: str, limit: float, skip: str = ""
) -> dict:
    """``engine`` on ``inst`` in encoding ``kind``: its status, seconds, and for a plan both
    validators' verdicts and its makespan. ``skip``: why not to run it (when it could)."""
    from unified_planning.shortcuts import PlanValidator, get_environment

    from benchmarks.lib.up_delivery import encode

    t0 = time.perf_counter()
    enc = encode(inst.site, planner.builder, world, inst.window, kind, bounded=engine in BOUNDED_INTS)
    row: dict[str, Any] = {"encoding": kind, "encode_seconds": round(time.perf_counter() - t0, 3)}
    factory = get_environment().factory
    if engine not in factory.engines:
        return {**row, "status": "not installed"}
    missing = sorted(set(enc.problem.kind.features) - set(factory.engine(engine).supported_kind().features))
    if missing:
        return {**row, "status": "unsupported", "missing_features": missing}
    if skip:
        return {**row, "status": "not run", "reason": skip}
    out = run_apart(lambda: solve_with(enc.problem, engine, limit), limit)
    row.update(status=out["status"], seconds=round(out["seconds"], 3), cpu_seconds=_rounded(out.get("cpu_seconds")))
    row.update({key: out[key] for key in ("error", "log") if out.get(key)})
    if not out.get("plan") or out["status"] == "timeout":
        return row
    plan = rebuild_plan(enc.problem, out["plan"])
    with PlanValidator(problem_kind=enc.problem.kind) as validator:
        check = validator.validate(enc.problem, plan)
    row["up_valid"] = check.status.name == "VALID"
    if not row["up_valid"]:
        row["up_reason"] = str(getattr(check, "reason", ""))[:300]
    try:
        robots, openings = enc.steps(plan)
    except ValueError as exc:
        row.update(valid=False, errors=[f"cannot read the plan back: {exc}"])
        return row
    windows = Windows(unavailable=[inst.window]) if inst.window else Windows()
    errors = validate(inst.site, world, robots, openings, windows)
    row.update(
        makespan=round(enc.finish(robots), 3),
        door_openings=len(openings),
        actions=len(out["plan"]),
        valid=not errors,
        errors=errors[:5],
    )
    return row


# ---------------------------------------------------------------------- the run


def ratio(peer: dict, iidp: dict) -> float | None:
    """Makespan over IIDP's, only when both plans passed every check."""
    if not (peer.get("valid") and peer.get("up_valid", True) and iidp.get("valid") and iidp.get("makespan")):
        return None
    return round(peer["makespan"] / iidp["makespan"], 4)


def run_instance(inst: Instance, args: argparse.Namespace, failures: dict[str, list[tuple[Instance, str]]]) -> dict:
    """IIDP, the joint program (small teams) and every engine run on ``inst``. ``failures`` (engine
    run -> the problems it found no valid plan for, and its status there) grows with this problem's
    and decides what is run: not a problem harder than one it failed on, nor anything after it said
    it found no plan (not a time-out) for a calibration problem."""
    # the joint program runs IIDP first and grounds before it solves: half the limit to solve, so
    # that it can hand back its best plan within the limit
    settings = PlannerSettings(time_limit=args.time_limit, joint_time_limit=args.time_limit / 2)
    planner = TaskPlanner(inst.site, settings)
    world = initial_world(inst.site)
    row: dict[str, Any] = {
        "site": inst.site_kind,
        "robots": inst.robots,
        "objects": inst.objects,
        "window": list(inst.window) if inst.window else None,
    }
    row["iidp"] = iidp = run_asp(inst, planner, world, "iidp", args.time_limit)
    log(f"{inst.label}: IIDP {iidp['status']}, makespan {iidp.get('makespan')} in {iidp['seconds']} s")
    if inst.site_kind == "calibration":
        pass
    elif inst.robots <= args.joint_max_robots:
        row["joint"] = joint = run_asp(inst, planner, world, "joint", args.time_limit)
        joint["ratio_to_iidp"] = ratio(joint, iidp)
        log(f"{inst.label}: joint {joint['status']}, makespan {joint.get('makespan')} in {joint['seconds']} s")
    else:
        row["joint"] = {"status": "not run", "reason": f"more than --joint-max-robots {args.joint_max_robots}"}
    row["peers"] = {}
    for engine, kind in args.engines:
        name = f"{engine}/{kind}"
        easier = [
            f
            for f, status in failures.get(name, [])
            if inst.harder_than(f) or (f.site_kind == "calibration" and status != "timeout")
        ]
        skip = f"no valid plan for {easier[0].label}" if easier and not args.run_all else ""
        peer = run_peer(inst, planner, world, engine, kind, args.time_limit, skip)
        peer["ratio_to_iidp"] = ratio(peer, iidp)
        if peer["ratio_to_iidp"] is None and peer["status"] not in ("unsupported", "not installed", "not run"):
            failures.setdefault(name, []).append((inst, peer["status"]))
        row["peers"][name] = peer
        log(
            f"{inst.label}: {name} {peer['status']}"
            + (f", makespan {peer['makespan']} (x{peer['ratio_to_iidp']})" if "makespan" in peer else "")
            + (f" in {peer['seconds']} s" if "seconds" in peer else "")
        )
    return row


def calibration(args: argparse.Namespace) -> list[Instance]:
    """Small generated problems (robots x objects each, no window), smallest first: where each
    engine stops, and that every engine can solve the encodings it is given."""
    return [
        Instance("calibration", r, r * k, None, loads_site(generate_site(r, k, seed=args.seed)))
        for r, k in args.calibration
    ]


def table(results: list[dict]) -> list[dict]:
    """One compact row per problem: makespan ratio to IIDP and seconds per method, or its status."""
    rows = []
    for r in results:
        cells: dict[str, Any] = {
            "site": r["site"],
            "robots": r["robots"],
            "window": r["window"] is not None,
            "iidp_makespan": r["iidp"]["makespan"],
            "iidp_seconds": r["iidp"]["seconds"],
        }
        methods = ([("joint", r["joint"])] if "joint" in r else []) + list(r["peers"].items())
        for name, m in methods:
            if m.get("ratio_to_iidp") is not None:
                cells[name] = f"x{m['ratio_to_iidp']:.3f} in {m['seconds']:.1f} s"
            elif m["status"] == "timeout":
                cells[name] = f"time-out ({m.get('seconds', 0):.0f} s)"
            elif m.get("valid") is False or m.get("up_valid") is False:
                cells[name] = "invalid plan"
            else:
                cells[name] = m["status"]
        rows.append(cells)
    return rows


def plot(calibration: list[dict], results: list[dict], limit: float, path: Path) -> None:
    """Makespan ratio to IIDP (top) and seconds (bottom): the calibration problems, then per team
    size without and with the window (generated sites as lines, the office as open squares). A
    time-out is a cross on the limit; no mark where a method did not run (unsupported, or it found
    no plan for a smaller problem). Methods at one size are set slightly apart to stay visible."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    every = ["iidp", "joint", *["/".join(r) for r in RUNS]]
    colours = dict(zip(every, plt.get_cmap("tab10").colors, strict=False))  # one colour per method in every plot
    rows = calibration + results
    methods = ["iidp", "joint", *(rows[0]["peers"] if rows else [])]
    fig, axes = plt.subplots(2, 3, figsize=(14, 8), sharey="row", gridspec_kw={"width_ratios": [1, 2, 2]})
    panels = [
        ("calibration (generated, no window)", calibration, ["calibration"]),
        ("no window", [r for r in results if r["window"] is None], ["generated", "office"]),
        ("with the human's unavailability window", [r for r in results if r["window"]], ["generated", "office"]),
    ]
    for col, (title, items, kinds) in enumerate(panels):
        top, bottom = axes[0][col], axes[1][col]
        slots = len(methods) * len(kinds)
        for k, method in enumerate(methods):
            for j, site_kind in enumerate(kinds):
                slot = (k * len(kinds) + j - (slots - 1) / 2) if method != "iidp" else 0
                style = "s" if site_kind == "office" else ("-o" if col else "o")
                xs, ratios, secs, outs = [], [], [], []
                for i, r in enumerate(items):
                    if r["site"] != site_kind:
                        continue
                    m = r["peers"].get(method) or r.get(method) or {}
                    # side by side: by a step on the calibration's axis, by a factor on the robots' (log) one
                    x = i + 0.06 * slot if col == 0 else r["robots"] * 1.012**slot
                    if method == "iidp" or m.get("ratio_to_iidp") is not None:
                        xs.append(x)
                        ratios.append(m.get("ratio_to_iidp", 1.0))
                        secs.append(m["seconds"])
                    elif m.get("status") == "timeout":
                        outs.append(x)
                face = "none" if site_kind == "office" else colours[method]
                kw = {"color": colours[method], "markerfacecolor": face}
                top.plot(xs, ratios, style, **kw)
                bottom.plot(xs, secs, style, **kw)
                bottom.plot(outs, [limit] * len(outs), "x", color=colours[method], markersize=9)
        top.set_title(title, fontsize=10)
        top.axhline(1.0, color="grey", lw=0.6)
        bottom.axhline(limit, color="grey", lw=0.6, ls="--")
        bottom.set_yscale("log")
        if col == 0:
            labels = [f"{r['robots']}x{r['objects'] // r['robots']}" for r in items]
            for ax in (top, bottom):
                ax.set_xticks(range(len(items)), labels)
            bottom.set_xlabel("robots x objects each")
        else:
            sizes = sorted({r["robots"] for r in items})
            for ax in (top, bottom):
                ax.set_xscale("log")
                ax.set_xticks(sizes, [str(s) for s in sizes])
                ax.minorticks_off()
            bottom.set_xlabel("robots (3 objects each)")
    axes[0][0].set_ylabel("makespan / IIDP's (valid plans only)")
    axes[1][0].set_ylabel(f"solve seconds (x: time-out at {limit:g} s)")
    handles = [Line2D([], [], color=colours[m], marker="o", label=m) for m in methods]
    handles.append(Line2D([], [], color="black", marker="s", markerfacecolor="none", ls="", label="office site"))
    fig.legend(handles=handles, loc="lower center", ncol=8, fontsize=8)
    fig.suptitle("Delivery plans: IIDP, the joint program and unified-planning engines")
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def versions() -> dict[str, str]:
    out = {}
    for name in PEER_PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def sizes(text: str) -> list[int]:
    return [int(x) for x in text.split(",") if x.strip()]


def engine_runs(text: str) -> list[tuple[str, str]]:
    runs = [tuple(item.strip().split("/", 1)) for item in text.split(",") if item.strip()]
    unknown = [f"{e}/{k}" for e, k in runs if (e, k) not in RUNS]
    if unknown:
        raise argparse.ArgumentTypeError(
            f"unknown {', '.join(unknown)} (one of {', '.join('/'.join(r) for r in RUNS)})"
        )
    return runs


def ladder(text: str) -> list[tuple[int, int]]:
    return [(int(r), int(k)) for r, k in (item.split("x") for item in text.split(",") if item.strip())]


def window(text: str) -> tuple[int, int]:
    t0, t1 = (int(x) for x in text.split(":"))
    if t1 <= t0:
        raise argparse.ArgumentTypeError("T1 must be greater than T0")
    return t0, t1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=sizes, default=[2, 3, 6, 12, 20], help="generated team sizes")
    parser.add_argument("--office", type=sizes, default=[2, 3], help="office team sizes (0: none; at most 3)")
    parser.add_argument("--objects", type=int, default=3, help="objects per robot on generated sites")
    parser.add_argument("--seed", type=int, default=0, help="generated sites' seed")
    parser.add_argument("--window", type=window, default=(60, 180), help="T0:T1, s the human opens no storage door")
    parser.add_argument("--time-limit", type=float, default=60.0, help="s for one solve (every method)")
    parser.add_argument("--joint-max-robots", type=int, default=3, help="largest team the joint program plans")
    parser.add_argument(
        "--engines", type=engine_runs, default=list(RUNS), help="ENGINE/ENCODING,... (default: all of them)"
    )
    parser.add_argument("--run-all", action="store_true", help="run engines on larger teams after they failed")
    parser.add_argument(
        "--calibration", type=ladder, default=CALIBRATION, help="small problems first, ROBOTSxOBJECTS,... ('': none)"
    )
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="where the JSON goes (besides stdout)")
    parser.add_argument("--plot", type=Path, default=DEFAULT_PLOT, help="where the plot goes")
    args = parser.parse_args(argv)
    args.office = [n for n in args.office if n > 0]
    if unified_planning is None:
        print("unified-planning is not installed: pip install -e '.[peers]'", file=sys.stderr)
        return 2
    warnings.filterwarnings("ignore", message="pkg_resources is deprecated")  # up-lpg 0.1.3 imports it
    from unified_planning.shortcuts import get_environment

    get_environment().credits_stream = None  # stdout carries the JSON document
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    failures: dict[str, list[tuple[Instance, str]]] = {}
    cal = [run_instance(inst, args, failures) for inst in calibration(args)]
    results = [run_instance(inst, args, failures) for inst in instances(args)]
    doc = {
        "benchmark": "peers",
        "command": " ".join(["python", "benchmarks/peers.py", *(argv if argv is not None else sys.argv[1:])]),
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "platform": platform.platform(),
            "load_average_at_start": [round(x, 2) for x in load_before],
            "load_average_at_end": [round(x, 2) for x in os.getloadavg()],
        },
        "versions": versions(),
        "settings": {
            "time_limit": args.time_limit,
            "objects_per_robot": args.objects,
            "seed": args.seed,
            "window": ["d_storage", *args.window],
            "joint_max_robots": args.joint_max_robots,
            "run_all": args.run_all,
            "engines": ["/".join(r) for r in args.engines],
            "engine_params": ENGINE_PARAMS,
            "grace_seconds": GRACE,
        },
        "wall_seconds": round(time.perf_counter() - t0, 1),
        "calibration_table": table(cal),
        "table": table(results),
        "calibration": cal,
        "results": results,
    }
    text = json.dumps(doc, indent=2)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n")
    plot(cal, results, args.time_limit, args.plot)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
