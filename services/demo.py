"""``arroch demo``: the main job on the packaged default site, all on localhost.

It checks and draws the site, then runs one whole mission under the supervisor
(``arroch up --until-done``): a Zenoh router, the planner, the restrictor, the simulator with its
simulated human and the virtual tablet camera (the human's tablet), the AR client drawing the robots
and their intents over that camera's frames, and the tablet page (viewer mode: the camera with its
overlay, and a map), whose URL and access token are printed as soon as it serves. The mission runs
in lockstep, so it takes seconds of wall time instead of the ~10 minutes it lasts on the site clock.
On a terminal (or with ``--linger``) the page and the services stay up after the mission, its
metrics printed, until Ctrl-C; elsewhere (CI, a pipe, ``--no-linger``) the demo ends with the mission.

Lockstep and the camera: site time only advances while the sim is not waiting for the planner, and
then many times faster than wall time, so a frame taken at a wall instant would be drawn over robots
that have moved on. In lockstep the sim therefore takes the tablet camera's frames on the *site*
clock: one every 30 site seconds (``arroch sim --camera-hold``), with time held still until the AR
client's overlay of that frame has come back (at most 1.5 wall seconds: ``--camera-hold-timeout``).
Every frame is then drawn over the world it shows; the overlays and the tablet page show the mission
in 30 s steps (about two per wall second), and the AR client keeps 5 of these frames as pictures, at
the same site times for the same mission (``services/ar_client/snapshots.py``). The ~24 holds
(a render and the AR client's turn each) replace the ~15 wall-rate frames and cost the demo about 3
wall seconds. ``arroch up ... --mode realtime`` shows the mission at its own pace.

The supervisor prints progress and the final metrics (a table: rounded, with units and what each
count means; the progress line's "door openings" are every door's, the paper's measure is the
human's) and leaves a run folder (metrics.json,
events.jsonl, the merged log, ``overlays/`` with a few overlay frames, ``run.mcap``: the recording of
the whole run, unless ``--no-record``); the site picture goes there too. Everything it starts is
stopped before it returns.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import TextIO

from protocol.site import default_site_path

SERVICES = "planner,restrictor,sim,ar,tablet"
CAMERA = "tablet"
# The tablet's announcement, as the supervisor passes it on: "[tablet]   https://HOST:PORT/?token=T&mode=viewer".
_URL = re.compile(r"^\[tablet\]\s+(https://\S+\?token=([A-Za-z0-9_\-]+)\S*)\s*$")


def _arroch(*args: str) -> list[str]:
    return [sys.executable, "-m", "services.cli", *args]


def _step(text: str, out: TextIO = sys.stdout) -> None:
    print(f"==> {text}", file=out, flush=True)


class TabletAnnouncement:
    """Watches the supervisor's output for the tablet page's URLs and says them once, clearly."""

    def __init__(self, out: TextIO) -> None:
        self.out = out
        self.urls: list[str] = []
        self.token: str | None = None
        self.announced = False

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
        if self.announced or not self.urls:
            return
        self.announced = True
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


def relay(lines: Iterable[str], out: TextIO, announcement: TabletAnnouncement) -> None:
    """Pass the supervisor's lines on, adding the tablet announcement when its URLs have come."""
    for raw in lines:
        line = raw.rstrip("\n")
        print(line, file=out, flush=True)
        announcement.feed(line)
    announcement.announce()


def lingers(args: argparse.Namespace, out: TextIO = sys.stdout) -> bool:
    """``--linger`` as asked, else only for a person at a terminal (CI, tests and pipes end with the mission)."""
    return args.linger if args.linger is not None else out.isatty()


def run_demo(args: argparse.Namespace) -> int:
    site_file = args.site or str(default_site_path())
    run_root = Path(args.run_dir)
    _step(f"checking the site {site_file}")
    if subprocess.run(_arroch("site", "check", site_file)).returncode != 0:
        return 1
    run_root.mkdir(parents=True, exist_ok=True)
    before = set(run_root.iterdir())

    _step(
        f"running one mission ({args.method}, seed {args.seed}, {args.mode}) with router, planner, restrictor, "
        f"sim (+ tablet camera), AR client and tablet page"
    )
    command = _arroch(
        "up",
        "--site",
        site_file,
        "--services",
        SERVICES,
        "--camera",
        CAMERA,
        "--method",
        args.method,
        "--mode",
        args.mode,
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
        *(["--linger"] if lingers(args) else []),
        *(["--view", "--view-port", str(args.view_port)] if args.view else []),
    )
    # Line by line through us, so the tablet's URL can be repeated where it is seen; the supervisor
    # stops its children on SIGINT/SIGTERM, which a terminal's Ctrl-C sends it (same process group).
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, errors="replace") as up:
        assert up.stdout is not None
        code = None
        while code is None:
            try:
                relay(up.stdout, sys.stdout, TabletAnnouncement(sys.stdout))
                code = up.wait()
            except KeyboardInterrupt:
                pass  # the supervisor got the same Ctrl-C and is stopping everything: wait for it
    new_runs = sorted(set(run_root.iterdir()) - before)
    run_dir = new_runs[-1] if new_runs else run_root
    subprocess.run(
        _arroch("site", "show", site_file, "--png", str(run_dir / "site.png")), check=False, stdout=subprocess.DEVNULL
    )
    if code != 0:
        print(f"the mission did not complete (exit {code}); see {run_dir}", file=sys.stderr)
        return code
    frames = sorted((run_dir / "overlays").glob("*.png"))
    _step(f"done; metrics, event log, site picture and {len(frames)} overlay frame(s) (overlays/) in {run_dir}")
    if (run_dir / "run.mcap").is_file():
        _step(
            f"recording {run_dir / 'run.mcap'}: open it in Foxglove (layout docs/foxglove-layout.json), "
            f"`arroch runs show {run_dir}` for its summary and timeline, `arroch replay` to play it back"
        )
    return 0


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
        help="after the mission, keep the tablet page and the services up until Ctrl-C "
        "(default: when the output is a terminal; --no-linger ends with the mission)",
    )
    parser.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    parser.set_defaults(func=run_demo)
