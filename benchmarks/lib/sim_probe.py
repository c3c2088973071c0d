"""Where a lockstep sim's mission wall time goes, measured inside the sim process of a sweep's trial.

Run as a script in place of ``arroch`` (``python benchmarks/lib/sim_probe.py OUT.json sim ...``) it
times, with ``time.perf_counter``, every engine step and every tick of the sim service (a step plus
publishing what it produced), runs the sim unchanged otherwise, and writes OUT.json when the mission
ends: ``engine_step_s`` (simulation), ``tick_s`` (simulation and publishing), ``steps``, the
process's CPU time. Timers read the clock only: the mission's outcome is the same as without them.

:func:`probing_sims` makes the sweep runner start its trials' sims so (the runner's command lines
are otherwise unchanged), one OUT.json per trial named after the trial.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = Path(__file__).resolve()


def install(out: Path) -> None:
    """Wrap the engine's step and the service's tick with timers; write ``out`` when the mission ends."""
    from services.sim.engine import Engine
    from services.sim.service import SimService

    for owner, name in ((Engine, "step"), (SimService, "_tick"), (SimService, "_finish")):
        if not callable(getattr(owner, name, None)):
            raise SystemExit(f"sim_probe: {owner.__name__}.{name} is gone; update benchmarks/lib/sim_probe.py")
    totals: dict[str, float] = {"engine_step_s": 0.0, "tick_s": 0.0, "steps": 0}
    step, tick, finish = Engine.step, SimService._tick, SimService._finish

    def timed_step(self: Engine) -> None:
        started = time.perf_counter()
        step(self)
        totals["engine_step_s"] += time.perf_counter() - started
        totals["steps"] += 1

    def timed_tick(self: SimService, wall: float) -> bool:
        started = time.perf_counter()
        try:
            return tick(self, wall)
        finally:
            totals["tick_s"] += time.perf_counter() - started

    def finish_and_write(self: SimService) -> None:
        finish(self)
        out.write_text(json.dumps({**totals, "cpu_s": time.process_time()}) + "\n", encoding="utf-8")

    Engine.step = timed_step  # type: ignore[method-assign]
    SimService._tick = timed_tick  # type: ignore[method-assign]
    SimService._finish = finish_and_write  # type: ignore[method-assign]


@contextmanager
def probing_sims(folder: Path) -> Iterator[None]:
    """While inside, the sweep runner's trials start their sim through this script, writing
    ``folder/<trial ident>.json``."""
    from runtime.launch.catalog import ARROCH
    from services.experiments import trial as trial_module

    original = trial_module.service_commands

    def probed(spec: Any, key: Any, **options: Any) -> dict[str, list[str]]:
        commands = original(spec, key, **options)
        sim = commands["sim"]
        if tuple(sim[: len(ARROCH)]) != ARROCH:
            raise RuntimeError(f"sim_probe: the sim's command no longer starts with {' '.join(ARROCH)}: {sim}")
        commands["sim"] = [sys.executable, str(SCRIPT), str(folder / f"{key.ident()}.json"), *sim[len(ARROCH) :]]
        return commands

    trial_module.service_commands = probed  # type: ignore[assignment]
    try:
        yield
    finally:
        trial_module.service_commands = original


def read(folder: Path, ident: str) -> dict[str, float] | None:
    """A trial's measures, or None when its sim wrote none (it did not reach the mission's end)."""
    path = folder / f"{ident}.json"
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (FileNotFoundError, json.JSONDecodeError):
        return None


if __name__ == "__main__":
    sys.path[0] = str(ROOT)  # the project, not this folder, is where imports start
    install(Path(sys.argv[1]))
    from services.cli import main

    sys.exit(main(sys.argv[2:]))
