"""End-to-end latency of the running system: a robot moves → the tablet's overlay shows it; the human
presses a feedback button → the robots get a plan that respects it. On one host, and across hosts.

Usage::

    .venv/bin/python benchmarks/e2e_latency.py [--seconds 40] [--presses 15] [--placements local,hosts]

Each placement runs the real services under ``arroch up`` — router, planner, restrictor, the sim in
real time (``--mode realtime --method no-feedback --seed 1``, so the only feedback is ours) with the
virtual tablet camera (``--camera tablet``: 640x480, 2 frames per second) and the AR client:

* ``local``: all on this machine, over loopback TCP (Zenoh's defaults, shared memory included);
* ``hosts``: three network namespaces on a private LAN with veth links, the secure profile (TLS,
  mutual authentication, access control): planning host (router, planner, restrictor), sim host,
  AR host — as ``docs/deploy.md`` lays them out. Needs root and iproute2; when namespaces cannot be
  made the JSON says why instead.

A probe (this script with ``probe``, a Zenoh client with the AR identity, on the AR host) measures:

* ``pose_to_overlay_ms``: a RobotPose's publication → the arrival at the probe of the overlay that
  draws it. Each Overlay names, in its ``pose_stamps`` field, the stamp of the pose it drew for each
  robot; the pose's publication time is its Zenoh timestamp, which the router gives it as it comes
  in (one link after the sim's put; same clock on every "host"). Counted for every robot an overlay
  draws (layer ``robot:<rid>``), from its freshest pose;
* ``pose_to_first_overlay_ms``: every pose → the first overlay that shows it or a newer pose of that
  robot, so waiting for the next camera frame included;
* the two parts of it: ``pose_age_at_frame_ms``, the drawn pose's age when the camera frame under
  the overlay was published (the sim renders the frame, ~0.1 s, in its loop, and publishes no pose
  meanwhile; the AR client applies pose updates between frames), and ``frame_to_overlay_ms``, the
  frame's publication (its Zenoh timestamp) → its overlay at the probe: transfer, localisation,
  drawing, transfer;
* ``press_to_ack_ms`` and ``press_to_plan_ms``: a feedback press (the AR client's sender:
  ``send_feedback`` on the ``feedback`` queryable; door_unavailable for 1 min and door_available_now
  on the human's door in turn, each replacing the other) → its acknowledgement, and → the arrival of
  the first TeamPlan whose ``constraints_version`` includes it; ``plan_solve_ms`` is that plan's own
  ``solve_time`` (the planner's replan, the rest being its settling, queueing and the messages);
* ``press_hops_ms``, the press → plan time by hop, from the Zenoh timestamps the router gives the
  ConstraintSet and the TeamPlan as they come in: ``to_restrictor`` (press → the ConstraintSet that
  holds it published: the AR client's query, the restrictor judging it and publishing),
  ``planner_waiting`` (ConstraintSet published → the plan's publication, less its solve: the
  planner receiving it, waiting for a replan already running, building the problems, dispatching),
  ``planner_solving`` (the plan's ``solve_time``) and ``plan_out`` (the plan's publication → its
  arrival at the AR host). Each press's hops add up to its ``press_to_plan``;
* on one host, the same from the tablet's page: the ``tablet`` service runs too, and every other press
  is sent as the page sends it (``{"type": "feedback"}`` on its WebSocket, answered by an ``ack``;
  the tablet server is the page's AR client and sends the Feedback on). ``press_hops_ms`` then has a
  ``direct`` and a ``page`` part; the page → AR client hop is the difference of their ``to_restrictor``
  medians (``page_to_ar_client_ms``). Across hosts only the AR client's sender presses.

Prints one JSON document on stdout (p50, p95, mean, max, n per figure and placement); progress on stderr.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import os
import platform
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import msgpack
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.lib import figures  # noqa: E402
from benchmarks.lib.figures import log  # noqa: E402
from protocol.codec import decode  # noqa: E402
from protocol.messages import ConstraintSet, Overlay, RobotPose, TeamPlan  # noqa: E402
from runtime.clock import WallClock  # noqa: E402
from runtime.service import Service  # noqa: E402
from runtime.transport import ZenohOptions, free_tcp_port  # noqa: E402
from tests.procs import Proc, arroch  # noqa: E402
from tests.tablet.helpers import start_tablet  # noqa: E402

CAMERA = "tablet"
HOPS = ("to_restrictor", "planner_waiting", "planner_solving", "plan_out")  # a press's way to its plan
MISSION = ["--mode", "realtime", "--method", "no-feedback", "--seed", "1", "--camera", CAMERA]
HUB_PORT = 7447


def summary(values: list[float]) -> dict[str, float]:
    return figures.summary(values, percentiles=(50, 95), scale=1000.0, digits=1)


# --------------------------------------------------------------------------- the probe (one process)


def zenoh_time(sample: Any, fallback: float) -> float:
    """A sample's Zenoh timestamp (given by the router on arrival when the publisher gave none), as Unix seconds."""
    stamp = sample.timestamp
    return stamp.get_time().timestamp() if stamp is not None else fallback


class PagePresser:
    """Presses feedback buttons as the tablet's page does: over its WebSocket (an event loop of its own)."""

    def __init__(self, url: str) -> None:
        self.base = url.split("?", 1)[0].rstrip("/")
        self.token = url.split("token=", 1)[1].split("&", 1)[0]
        self.loop = asyncio.new_event_loop()
        threading.Thread(target=self.loop.run_forever, name="page", daemon=True).start()
        self.acks: dict[int, asyncio.Future] = {}
        self.ids = itertools.count(1)
        self.ws: Any = None
        asyncio.run_coroutine_threadsafe(self._connect(), self.loop).result(timeout=30)

    async def _connect(self) -> None:
        import aiohttp

        self.http = aiohttp.ClientSession(connector=aiohttp.TCPConnector(ssl=False))  # the run's own certificate
        self.ws = await self.http.ws_connect(f"{self.base}/ws?token={self.token}", headers={"Origin": self.base})
        self.loop.create_task(self._read())

    async def _read(self) -> None:
        async for message in self.ws:
            if message.type.name != "TEXT":
                continue
            doc = json.loads(message.data)
            waiting = self.acks.pop(doc.get("id"), None) if doc.get("type") == "ack" else None
            if waiting is not None and not waiting.done():
                waiting.set_result(doc)

    async def _press(self, kind: str, params: dict[str, Any]) -> dict[str, Any]:
        n = next(self.ids)
        self.acks[n] = self.loop.create_future()
        await self.ws.send_str(json.dumps({"type": "feedback", "id": n, "kind": kind, "params": params}))
        return await self.acks[n]

    def press(self, kind: str, params: dict[str, Any], timeout: float) -> dict[str, Any] | None:
        """The page's ack (``status``, ``constraints_version``), or None without one in time."""
        try:
            return asyncio.run_coroutine_threadsafe(self._press(kind, params), self.loop).result(timeout)
        except TimeoutError:
            return None


class Probe:
    """Records poses, overlays and plans as they arrive, and presses feedback buttons."""

    def __init__(self, client: Service, door: str, page: PagePresser | None = None) -> None:
        self.client = client
        self.door = door
        self.page = page
        self.lock = threading.Lock()
        self.poses: dict[str, list[tuple[float, float]]] = {}  # rid -> [(stamp, publication time)]
        self.overlays: list[dict[str, Any]] = []
        self.frames: dict[int, float] = {}  # camera frame seq -> publication time
        self.plans: list[tuple[float, int, float, float]] = []  # (arrival, constraints_version, solve_time, published)
        self.constraint_sets: dict[int, float] = {}  # version -> publication time
        self.unstamped = 0

    def listen(self) -> None:
        keys, session = self.client.keys, self.client.session
        for key, handler in (
            (keys.robot_pose("*"), self._on_pose),
            (keys.overlay(CAMERA), self._on_overlay),
            (keys.plan(), self._on_plan),
            (keys.camera_frame(CAMERA), self._on_frame),
            (keys.constraints(), self._on_constraints),
        ):
            self.client._declared.append(session.declare_subscriber(key, handler))  # undeclared when the client closes

    def _on_pose(self, sample: Any) -> None:
        arrival = time.time()
        pose = decode(sample.payload.to_bytes(), RobotPose)
        with self.lock:
            self.unstamped += sample.timestamp is None
            self.poses.setdefault(pose.robot, []).append((pose.stamp, zenoh_time(sample, arrival)))

    def _on_frame(self, sample: Any) -> None:
        arrival = time.time()
        seq = msgpack.unpackb(sample.payload.to_bytes()).get(
            "seq"
        )  # only the envelope's seq: no need to decode the JPEG
        with self.lock:
            self.frames[int(seq)] = zenoh_time(sample, arrival)

    def _on_overlay(self, sample: Any) -> None:
        arrival = time.time()
        payload = sample.payload.to_bytes()
        overlay = decode(payload, Overlay)
        stamps = msgpack.unpackb(payload).get("pose_stamps", {})  # an extra field: decode() drops it
        drawn = {p.layer.split(":", 1)[1] for p in overlay.primitives if p.layer.startswith("robot:")}
        with self.lock:
            self.overlays.append(
                {
                    "arrival": arrival,
                    "ok": overlay.ok,
                    "frame": overlay.frame_seq,
                    "drawn": {rid: float(stamps[rid]) for rid in drawn if rid in stamps},
                }
            )

    def _on_plan(self, sample: Any) -> None:
        arrival = time.time()
        plan = decode(sample.payload.to_bytes(), TeamPlan)
        with self.lock:
            self.plans.append((arrival, plan.constraints_version, plan.solve_time, zenoh_time(sample, arrival)))

    def _on_constraints(self, sample: Any) -> None:
        arrival = time.time()
        cs = decode(sample.payload.to_bytes(), ConstraintSet)
        with self.lock:
            self.constraint_sets.setdefault(cs.version, zenoh_time(sample, arrival))

    def wait_live(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                if self.plans and any(o["ok"] for o in self.overlays):
                    return
            time.sleep(0.1)
        raise RuntimeError(f"no plan and localised overlay within {timeout:.0f} s")

    def press(self, kind: str, params: dict[str, Any], via_page: bool = False) -> dict[str, Any]:
        from runtime.feedback_client import send_feedback

        via = "page" if via_page and self.page is not None else "direct"
        pressed = time.time()
        if self.page is not None and via == "page":
            answer = self.page.press(kind, params, timeout=10.0)
            acked = time.time()
            if answer is None or answer.get("status") != "accepted":
                return {"kind": kind, "via": via, "ack": None if answer is None else answer.get("reason")}
            version = int(answer["constraints_version"])
        else:
            ack = send_feedback(self.client, kind, params, timeout=10.0)
            acked = time.time()
            if ack is None or not ack.accepted:
                return {"kind": kind, "via": via, "ack": None if ack is None else ack.reason}
            version = ack.constraints_version
        deadline = time.monotonic() + 15.0
        planned = None
        while planned is None and time.monotonic() < deadline:
            with self.lock:
                planned = next(
                    (row for row in self.plans if row[1] >= version and row[0] >= pressed),
                    None,
                )
            time.sleep(0.002)
        with self.lock:
            published = self.constraint_sets.get(version)
        out: dict[str, Any] = {
            "kind": kind,
            "via": via,
            "press_to_ack": acked - pressed,
            "press_to_plan": None if planned is None else planned[0] - pressed,
            "solve_time": None if planned is None else planned[2],
            "constraints_version": version,
        }
        if planned is not None and published is not None:
            arrival, _, solve, plan_published = planned
            out["hops"] = {
                "to_restrictor": published - pressed,
                "planner_waiting": plan_published - published - solve,
                "planner_solving": solve,
                "plan_out": arrival - plan_published,
            }
        return out

    def presses(self, count: int, gap: float, until: float) -> list[dict[str, Any]]:
        choices = itertools.cycle(
            [("door_unavailable", {"door": self.door, "minutes": 1}), ("door_available_now", {"door": self.door})]
        )
        out: list[dict[str, Any]] = []
        while len(out) < count and time.monotonic() < until:
            out.append(self.press(*next(choices), via_page=len(out) % 2 == 1))  # every other one from the page
            time.sleep(gap)
        return out

    def pose_figures(self) -> dict[str, list[float]]:
        """Seconds from each drawn pose's publication to its overlay, and its age when the frame
        under it was published; from every pose to the first overlay showing it; from each frame's
        publication to its overlay."""
        with self.lock:
            poses = {rid: sorted(rows) for rid, rows in self.poses.items()}
            overlays = sorted(self.overlays, key=lambda o: o["arrival"])
            frames = dict(self.frames)
        drawn_age: list[float] = []
        age_at_frame: list[float] = []
        first_shown: list[float] = []
        frame_to_overlay = [o["arrival"] - frames[o["frame"]] for o in overlays if o["ok"] and o["frame"] in frames]
        for rid, rows in poses.items():
            stamps = np.array([s for s, _ in rows])
            published = dict(rows)
            previous: float | None = None  # the stamp the previous overlay drew for this robot (None: not drawn)
            for overlay in overlays:
                stamp = overlay["drawn"].get(rid)
                if stamp is None or stamp not in published:
                    previous = None  # out of view (or lost): the poses meanwhile were shown by nobody
                    continue
                drawn_age.append(overlay["arrival"] - published[stamp])
                if overlay["frame"] in frames:
                    age_at_frame.append(frames[overlay["frame"]] - published[stamp])
                if previous is not None and stamp > previous:
                    # Every pose after the previous overlay's, up to this one's, is first shown now.
                    lo, hi = (
                        np.searchsorted(stamps, previous, side="right"),
                        np.searchsorted(stamps, stamp, side="right"),
                    )
                    first_shown += [overlay["arrival"] - published[s] for s in stamps[lo:hi]]
                previous = stamp if previous is None else max(previous, stamp)
        return {
            "drawn": drawn_age,
            "age_at_frame": age_at_frame,
            "first": first_shown,
            "frame_to_overlay": frame_to_overlay,
        }


def hop_figures(presses: list[dict[str, Any]]) -> dict[str, Any]:
    """Each hop's summary over all presses and, when some came from the page, per way in (the AR
    client's sender, the page), with the page → AR client hop: how much longer a press from the page
    takes to reach the restrictor (medians)."""

    def of(rows: list[dict[str, Any]]) -> dict[str, Any]:
        return {hop: summary([p["hops"][hop] for p in rows if "hops" in p]) for hop in HOPS}

    out: dict[str, Any] = of(presses)
    ways = {via: [p for p in presses if p.get("via") == via] for via in ("direct", "page")}
    if ways["page"]:
        out |= {via: of(rows) for via, rows in ways.items()}
        medians = [out[via]["to_restrictor"].get("p50") for via in ("page", "direct")]
        if None not in medians:
            out["page_to_ar_client_ms"] = round(medians[0] - medians[1], 1)
    return out


def run_probe(args: argparse.Namespace) -> int:
    from protocol.site import load_site

    door = next(d for d, o in load_site(None).doors.items() if o.human_operated)
    options = (
        ZenohOptions(config_file=args.zenoh_config)
        if args.zenoh_config
        else ZenohOptions(mode="client", connect=[args.connect])
    )
    client = Service("probe", args.namespace, options, clock=WallClock())
    client.open()
    try:
        probe = Probe(client, door, PagePresser(args.page) if args.page else None)
        probe.listen()
        probe.wait_live(args.live_timeout)
        started = time.monotonic()
        presses = probe.presses(args.presses, args.gap, started + args.seconds)
        time.sleep(max(0.0, started + args.seconds - time.monotonic()))
        elapsed = time.monotonic() - started
        figures = probe.pose_figures()
        with probe.lock:
            overlays = list(probe.overlays)
        result = {
            "pose_to_overlay_ms": summary(figures["drawn"]),
            "pose_to_first_overlay_ms": summary(figures["first"]),
            "pose_age_at_frame_ms": summary(figures["age_at_frame"]),
            "frame_to_overlay_ms": summary(figures["frame_to_overlay"]),
            "press_to_ack_ms": summary([p["press_to_ack"] for p in presses if "press_to_ack" in p]),
            "press_to_plan_ms": summary([p["press_to_plan"] for p in presses if p.get("press_to_plan") is not None]),
            "plan_solve_ms": summary([p["solve_time"] for p in presses if p.get("solve_time") is not None]),
            "press_hops_ms": hop_figures(presses),
            "presses": len(presses),
            "presses_without_plan": sum(1 for p in presses if p.get("press_to_plan") is None),
            "overlays_per_s": round(len(overlays) / elapsed, 2),
            "overlays_localised": round(sum(o["ok"] for o in overlays) / max(len(overlays), 1), 3),
            "overlays_with_robots": sum(1 for o in overlays if o["drawn"]),
            "poses_without_zenoh_timestamp": probe.unstamped,
        }
        print(json.dumps(result), flush=True)
        return 0
    finally:
        client.close()


# --------------------------------------------------------------------------- placements


def probe_argv(zenoh: list[str], namespace: str, args: argparse.Namespace, page: str = "") -> list[str]:
    return [
        sys.executable,
        str(Path(__file__).resolve()),
        "probe",
        *zenoh,
        "--namespace",
        namespace,
        "--seconds",
        str(args.seconds),
        "--presses",
        str(args.presses),
        "--gap",
        str(args.gap),
        *(["--page", page] if page else []),
    ]


def collect(probe: Proc, timeout: float) -> dict[str, Any]:
    line = probe.wait_for('"press_to_plan_ms"', timeout=timeout)
    return json.loads(line)


def run_local(args: argparse.Namespace, workdir: Path) -> dict[str, Any]:
    namespace = f"e2e{os.getpid()}"
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    env = {"XDG_STATE_HOME": str(workdir / "state")}
    procs: list[Proc] = []

    def track(proc: Proc) -> Proc:
        procs.append(proc)
        return proc

    try:
        up = Proc(
            arroch(
                "up",
                "--services",
                "planner,restrictor,sim,ar",
                *MISSION,
                "--namespace",
                namespace,
                "--router-listen",
                endpoint,
                "--run-dir",
                str(workdir / "runs-local"),
                "--progress",
                "off",
                "--log-level",
                "WARNING",
            ),
            env=env,
            name="up",
        )
        procs.append(up)
        up.wait_for("router ready", timeout=60)
        tablet = start_tablet(lambda argv, name: track(Proc(argv, env=env, name=name)), endpoint, namespace, workdir)
        probe = Proc(probe_argv(["--connect", endpoint], namespace, args, tablet.url), env=env, name="probe")
        procs.append(probe)
        return collect(probe, args.seconds + 120)
    finally:
        for proc in reversed(procs):
            proc.stop()


def run_hosts(args: argparse.Namespace, workdir: Path) -> dict[str, Any]:
    if os.geteuid() != 0:
        return {"skipped": f"network namespaces need root (running as uid {os.geteuid()})"}
    import pytest

    from tests.deploy.netns import Lan
    from tests.deploy.secure import make_pki, render_configs

    namespace = f"e2e{os.getpid()}h"
    try:
        lan = Lan(["planning", "sim", "ar"]).create()
    except (pytest.fail.Exception, OSError) as exc:  # Lan.create reports failure the pytest way
        return {"skipped": f"could not make the namespaces: {exc}"}
    try:
        hub = lan.hub.address
        certs, foreign = make_pki(workdir / "pki", sans=[f"router={hub}"])
        endpoint = f"tls/{hub}:{HUB_PORT}"
        configs = render_configs(certs, foreign, workdir / "zenoh", router=endpoint, listen=endpoint)

        def up(host: str, *extra: str) -> Proc:
            return lan.spawn(
                host,
                arroch(
                    "up",
                    "--namespace",
                    namespace,
                    "--zenoh-config-dir",
                    str(configs),
                    "--progress",
                    "off",
                    "--log-level",
                    "WARNING",
                    "--run-dir",
                    str(workdir / f"runs-{host}"),
                    *extra,
                ),
                name=host,
            )

        planning = up("planning", "--services", "planner,restrictor")
        planning.wait_for("router ready", timeout=60)
        up("ar", "--no-router", "--services", "ar")
        up("sim", "--no-router", "--services", "sim", *MISSION)
        probe = lan.spawn(
            "ar", probe_argv(["--zenoh-config", str(configs / "ar.json5")], namespace, args), name="probe"
        )
        result = collect(probe, args.seconds + 150)
        result["link"] = f"TLS over veth, router {endpoint}"
        return result
    finally:
        lan.destroy()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("role", nargs="?", default="run", choices=("run", "probe"), help=argparse.SUPPRESS)
    parser.add_argument("--seconds", type=float, default=40.0, help="measuring time per placement (default 40)")
    parser.add_argument("--presses", type=int, default=15, help="feedback presses per placement (default 15)")
    parser.add_argument(
        "--gap", type=float, default=1.0, help="seconds between a press's plan and the next press (default 1)"
    )
    parser.add_argument("--placements", default="local,hosts", help="local, hosts or both (default local,hosts)")
    parser.add_argument("--connect", help=argparse.SUPPRESS)
    parser.add_argument("--zenoh-config", help=argparse.SUPPRESS)
    parser.add_argument("--namespace", help=argparse.SUPPRESS)
    parser.add_argument("--page", help=argparse.SUPPRESS)  # the tablet's URL, token included: press from the page
    parser.add_argument("--live-timeout", type=float, default=90.0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == "probe":
        return run_probe(args)
    placements = [p.strip() for p in args.placements.split(",") if p.strip()]
    unknown = [p for p in placements if p not in ("local", "hosts")]
    if unknown:
        parser.error(f"--placements: unknown {', '.join(unknown)} (local, hosts)")
    results: dict[str, Any] = {}
    load_at_start = round(os.getloadavg()[0], 2)
    with tempfile.TemporaryDirectory(prefix="arroch-e2e-") as tmp:
        for placement in placements:
            log(f"== {placement}")
            runner = run_local if placement == "local" else run_hosts
            results[placement] = runner(args, Path(tmp) / placement)
            log(json.dumps(results[placement]))
    print(
        json.dumps(
            {
                "benchmark": "e2e_latency",
                "machine": {
                    "python": platform.python_version(),
                    "cpus": os.cpu_count(),
                    "load_avg_1min": round(os.getloadavg()[0], 2),
                    "load_avg_1min_at_start": load_at_start,
                },
                "setup": {"mission": " ".join(MISSION), "seconds": args.seconds, "presses": args.presses},
                **results,
            },
            indent=1,
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
