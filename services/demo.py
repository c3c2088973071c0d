"""``arroch demo``: the main job on the packaged default site, all on localhost.

It checks the site, starts a Zenoh router and the tablet page (viewer mode: the tablet camera with
its overlay, and a map) and prints the page's address and access token first, so a browser can be
there before anything moves. Then it runs one whole mission under the supervisor (``arroch up
--until-done`` on that router): the planner, the restrictor, the simulator with its simulated human
and the virtual tablet camera (the human's tablet), the AR client, and the recorder (``run.mcap``).

Pace: the mission runs in lockstep (the same mission whatever the machine's load), capped at
``--pace`` times real time (10: the ~650 s mission takes about a minute, slow enough to follow on
the page; ``--pace 0``: as fast as it goes, ~15 s). In lockstep the sim publishes robot poses at 20 Hz
and camera frames at 0.5 Hz of *site* time (``arroch sim --pose-rate``, ``--camera-hold``), each
frame with time held still until the AR client's overlay of it has come back, so the page and the
recording show every frame drawn over the world it shows. ``arroch up ... --mode realtime`` shows
the mission at its own pace.

After the mission: on a terminal (or with ``--linger``) the page goes on showing the run, the
recording replayed in a loop at the same pace (``arroch replay --loop``), until Ctrl-C; elsewhere
(CI, a pipe, ``--no-linger``) the demo ends with the mission.

The supervisor prints progress and the final metrics (a table: rounded, with units and what each
count means; the progress line's "door openings" are every door's, the paper's measure is the
human's) and leaves a run folder (metrics.json, events.jsonl, the merged log, ``overlays/`` with a
few overlay frames, ``run.mcap``: the recording of the whole run, unless ``--no-record``); the site
picture goes there too. Everything it starts is stopped before it returns.
"""

from __future__ import annotations

import argparse
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

from protocol.site import default_site_path
from runtime.launch.children import Child, stop_all
from runtime.transport import free_tcp_port

SERVICES = "planner,restrictor,sim,ar"  # under the supervisor; the router and the page are the demo's own
CAMERA = "tablet"
WATCHED_CAMERA_EVERY = 2.0  # site s between camera frames: people watch the demo and its recording
NAMESPACE = "demo"
DEFAULT_PACE = 10.0  # lockstep at most this many times real time: a mission a person can follow
ROUTER_READY = "router ready"
PAGE_TIMEOUT = 60.0  # wall s for the tablet page to say where it is
STOP_TIMEOUT = 10.0  # wall s a child gets after SIGTERM (the supervisor stops its own children meanwhile)
# What the page shows, replayed after the mission (its overlays are the page's own).
REPLAYED = ("camera/*/frame", "robot/*/pose", "robot/*/status", "intent/*", "door/*/state", "clock", "constraints")
# The page's announcement, as the tablet prints it: "  https://HOST:PORT/?token=T&mode=viewer".
_URL = re.compile(r"^\s*(https://\S+\?token=([A-Za-z0-9_\-]+)\S*)\s*$")


def _arroch(*args: str) -> list[str]:
    return [sys.executable, "-m", "services.cli", *args]


def _step(text: str, out: TextIO = sys.stdout) -> None:
    print(f"==> {text}", file=out, flush=True)


class TabletAnnouncement:
    """Watches the tablet's output for the page's URLs and says them once, clearly."""

    def __init__(self, out: TextIO) -> None:
        self.out = out
        self.urls: list[str] = []
        self.token: str | None = None
        self.announced = threading.Event()

    def feed(self, line: str) -> None:
        match = _URL.match(line)
        if match:
            self.urls.append(match.group(1))
            self.token = match.group(2)
            if "://127.0.0.1:" in match.group(1):
                self.announce()  # loopback comes last: the block is complete
        elif self.urls:
            self.announce()  # the first line after the URL block

    def announce(self) -> None:
        if self.announced.is_set() or not self.urls:
            return
        self.announced.set()
        local = [u for u in self.urls if "://127.0.0.1:" in u or "://localhost:" in u]
        _step("tablet page (viewer: the tablet camera with its overlay, and a map of the robots):", self.out)
        for url in dict.fromkeys([*local, *self.urls]):
            print(f"      {url}", file=self.out)
        print(
            f"    access token: {self.token}  (this run's key; the browser will warn about the certificate:"
            f" its authority is at /ca.pem)",
            file=self.out,
            flush=True,
        )


def lingers(args: argparse.Namespace, out: TextIO = sys.stdout) -> bool:
    """``--linger`` as asked, else only for a person at a terminal (CI, tests and pipes end with the mission)."""
    return args.linger if args.linger is not None else out.isatty()


class Demo:
    """The demo's own children (router, tablet page, mission, replay) and their output."""

    def __init__(self, args: argparse.Namespace, site_file: str, out: TextIO = sys.stdout) -> None:
        self.args = args
        self.site_file = site_file
        self.out = out
        self.endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
        self.announcement = TabletAnnouncement(out)
        self.children: list[Child] = []
        self._lock = threading.Lock()

    def _line(self, name: str, line: str) -> None:
        with self._lock:
            if name == "tablet":
                self.announcement.feed(line)
                if _URL.match(line) or line.startswith("Tablet page"):
                    return  # said once, by the announcement
            print(line if name == "up" else f"[{name}] {line}", file=self.out, flush=True)

    def start(self, name: str, argv: list[str], ready: str | None = None) -> Child:
        child = Child(name, argv, on_line=self._line, restart=False)
        self.children.append(child)
        child.start(ready)
        return child

    def zenoh(self) -> list[str]:
        return ["--namespace", NAMESPACE, "--site", self.site_file, "--connect", self.endpoint]

    def open_page(self) -> bool:
        """The router and the tablet page; True once the page has said where it is."""
        quiet = ["--log-level", "WARNING"]
        router = self.start("router", _arroch("router", "--listen", self.endpoint, *quiet), ROUTER_READY)
        if not _wait(lambda: router.ready.is_set(), router, PAGE_TIMEOUT):
            print("the Zenoh router did not start (its output is above)", file=sys.stderr)
            return False
        page = ["--port", "0", "--no-qr", "--camera-source", f"sim:{CAMERA}"]
        tablet = self.start("tablet", _arroch("tablet", *self.zenoh(), *page, *quiet))
        if not _wait(self.announcement.announced.is_set, tablet, PAGE_TIMEOUT):
            print("the tablet page did not start (its output is above)", file=sys.stderr)
            return False
        return True

    def mission(self, run_root: Path) -> int:
        args = self.args
        pace = ["--rate", f"{args.pace:g}"] if args.mode != "realtime" and args.pace > 0 else []
        command = _arroch(
            "up",
            *self.zenoh(),
            "--no-router",
            "--services",
            SERVICES,
            "--camera",
            CAMERA,
            "--camera-every",
            f"{WATCHED_CAMERA_EVERY:g}",
            "--method",
            args.method,
            "--mode",
            args.mode,
            *pace,
            "--seed",
            str(args.seed),
            "--until-done",
            "--timeout",
            str(args.timeout),
            "--run-dir",
            str(run_root),
            "--progress",
            "line",
            "--log-level",
            args.log_level or "WARNING",
            "--record" if args.record else "--no-record",
            *(["--view", "--view-port", str(args.view_port)] if args.view else []),
        )
        up = self.start("up", command)
        while not up.wait(0.5):
            pass
        up.flush_output()
        return up.returncode() or 0

    def replay(self, recording: Path) -> None:
        """The recording on the page again and again, at the mission's pace, until stopped."""
        rate = self.args.pace if self.args.mode != "realtime" and self.args.pace > 0 else 1.0
        only = [arg for pattern in REPLAYED for arg in ("--only", pattern)]
        command = _arroch("replay", str(recording), *self.zenoh(), "--loop", "--rate", f"{rate:g}", *only)
        self.start("replay", [*command, "--log-level", "WARNING"])

    def stop(self) -> None:
        stop_all(self.children, STOP_TIMEOUT)
        for child in self.children:
            child.flush_output()


def _wait(done: Callable[[], bool], child: Child, timeout: float) -> bool:
    """Until ``done()``; False when ``child`` exits first or ``timeout`` wall s pass."""
    deadline = time.monotonic() + timeout
    while not done():
        if not child.running() or time.monotonic() > deadline:
            return done()
        time.sleep(0.05)
    return True


def _terminate_as_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt  # SIGTERM stops the demo as Ctrl-C does: everything it started, stopped


def run_demo(args: argparse.Namespace) -> int:
    site_file = args.site or str(default_site_path())
    if not (args.pace >= 0):
        print(f"--pace must be >= 0 (0: as fast as it goes), got {args.pace:g}", file=sys.stderr)
        return 2
    run_root = Path(args.run_dir)
    _step(f"checking the site {site_file}")
    checked = subprocess.run(_arroch("site", "check", site_file)).returncode
    if checked != 0:
        return checked
    run_root.mkdir(parents=True, exist_ok=True)
    before = set(run_root.iterdir())
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _terminate_as_interrupt)
    demo = Demo(args, site_file)
    lingering = False
    try:
        if not demo.open_page():
            return 1
        pace = f"at most {args.pace:g}x real time" if args.mode != "realtime" and args.pace > 0 else "unpaced"
        _step(
            f"running one mission ({args.method}, seed {args.seed}, {args.mode}, {pace}) with planner, restrictor, "
            f"sim (+ tablet camera) and AR client"
        )
        code = demo.mission(run_root)
        new_runs = sorted(set(run_root.iterdir()) - before)
        run_dir = new_runs[-1] if new_runs else run_root
        subprocess.run(
            _arroch("site", "show", site_file, "--png", str(run_dir / "site.png")),
            check=False,
            stdout=subprocess.DEVNULL,
        )
        if code != 0:
            print(f"the mission did not complete (exit {code}); see {run_dir}", file=sys.stderr)
            return code
        frames = sorted((run_dir / "overlays").glob("*.png"))
        _step(f"done; metrics, event log, site picture and {len(frames)} overlay frame(s) (overlays/) in {run_dir}")
        recording = run_dir / "run.mcap"
        if recording.is_file():
            _step(
                f"recording {recording}: open it in Foxglove (layout docs/foxglove-layout.json), "
                f"`arroch runs show {run_dir}` for its summary and timeline, `arroch replay` to play it back"
            )
        if lingers(args):
            lingering = True
            if recording.is_file():
                demo.replay(recording)
                _step("mission over: the page replays its recording in a loop until Ctrl-C")
            else:
                _step("mission over: the page stays up (no recording to replay) until Ctrl-C")
            while True:
                time.sleep(3600)
        return 0
    except KeyboardInterrupt:
        return 0 if lingering else 130  # after the mission, Ctrl-C is how a lingering demo ends
    finally:
        demo.stop()


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "demo",
        help="run one mission on the default site (localhost), with the AR view, and print its metrics",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--site", help="site file (default: the packaged office site)")
    parser.add_argument(
        "--method", default="arroch", choices=("arroch", "no-feedback", "no-comm"), help="method (default arroch)"
    )
    parser.add_argument(
        "--mode", default="lockstep", choices=("lockstep", "realtime", "rate"), help="sim clock mode (default lockstep)"
    )
    parser.add_argument(
        "--pace",
        type=float,
        default=DEFAULT_PACE,
        metavar="K",
        help=f"lockstep: at most K times real time (default {DEFAULT_PACE:g}: about a minute; 0: as fast as it goes)",
    )
    parser.add_argument("--seed", type=int, default=1, help="seed of the simulated human (default 1)")
    parser.add_argument(
        "--timeout", type=float, default=600.0, help="give up after this many wall seconds (default 600)"
    )
    parser.add_argument("--run-dir", default="runs", help="folder of run folders (default runs/)")
    parser.add_argument(
        "--record",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="record the run to <run folder>/run.mcap (default; --no-record turns it off)",
    )
    parser.add_argument(
        "--view", action="store_true", help="serve the run live to Foxglove (ws://127.0.0.1:--view-port)"
    )
    parser.add_argument("--view-port", type=int, default=8765, help="with --view: the port (default 8765)")
    parser.add_argument(
        "--linger",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="after the mission, the tablet page goes on showing it (its recording in a loop) until Ctrl-C "
        "(default: when the output is a terminal; --no-linger ends with the mission)",
    )
    parser.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    parser.set_defaults(func=run_demo)
