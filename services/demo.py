"""``arroch demo``: the main job on the packaged default site, on localhost.

Today it: checks and renders the default site, starts a Zenoh router and the protocol echo
service as separate processes, sends RobotPoses through the protocol layer and prints the
round-trip figures. Everything it starts is stopped before it returns.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import subprocess
import sys
import time
from pathlib import Path

from protocol.site import default_site_path
from protocol.transport import free_tcp_port


def _arroch(*args: str) -> list[str]:
    return [sys.executable, "-m", "services.cli", *args]


def _step(text: str) -> None:
    print(f"==> {text}", flush=True)


def _wait_line(proc: subprocess.Popen, text: str, timeout: float) -> None:
    """Read the child's output until a line contains ``text`` (its output is echoed, indented)."""
    deadline = time.monotonic() + timeout
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            raise RuntimeError(f"{proc.args[3]} exited before it was ready")
        if text in line:
            return
    raise RuntimeError(f"{proc.args[3]} not ready within {timeout} s")


def run_demo(args: argparse.Namespace) -> int:
    run_dir = Path(args.run_dir or f"runs/{dt.datetime.now():%Y%m%d-%H%M%S}-demo")
    run_dir.mkdir(parents=True, exist_ok=True)
    site_file = args.site or str(default_site_path())
    _step(f"checking the site {site_file}")
    subprocess.run(_arroch("site", "check", site_file), check=True)
    png = run_dir / "site.png"
    subprocess.run(_arroch("site", "show", site_file, "--png", str(png)), check=True)
    print(f"    top-down picture: {png}")

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    children: list[subprocess.Popen] = []
    try:
        _step(f"starting a Zenoh router on {endpoint}")
        router = subprocess.Popen(_arroch("router", "--listen", endpoint, "--log-level", "WARNING"),
                                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        children.append(router)
        _wait_line(router, "router ready", 20)
        _step("starting the protocol echo service (arroch ping serve)")
        echo = subprocess.Popen(_arroch("ping", "serve", "--connect", endpoint, "--namespace", "demo", "--log-level", "WARNING"),
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        children.append(echo)
        _step("sending RobotPoses through the protocol layer and back")
        out = subprocess.run(
            _arroch("ping", "send", "--connect", endpoint, "--namespace", "demo", "--count", str(args.count), "--json"),
            check=True, capture_output=True, text=True,
        ).stdout
        figures = json.loads(out)
        (run_dir / "ping.json").write_text(json.dumps(figures, indent=2))
        print(f"    {figures.get('received', '?')} of {figures.get('sent', '?')} poses came back; "
              f"round trip p50 {figures.get('p50_us', 0):.0f} µs, p99 {figures.get('p99_us', 0):.0f} µs")
    finally:
        for child in reversed(children):
            child.terminate()
        for child in children:
            try:
                child.wait(5)
            except subprocess.TimeoutExpired:
                child.kill()
    _step(f"done; results in {run_dir}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("demo", help="run the main job on the default site (localhost)", description=__doc__)
    parser.add_argument("--site", help="site file (default: the packaged office site)")
    parser.add_argument("--count", type=int, default=200, help="poses to send (default 200)")
    parser.add_argument("--run-dir", help="where to write results (default runs/<time>-demo)")
    parser.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    parser.set_defaults(func=run_demo)
