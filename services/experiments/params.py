"""``params.json``: the model a sweep's results come from, as the simulator reported it.

Every trial's metrics carry ``params`` (the human model, the engine, the site's parameters, the
clock mode). Those that describe the trial itself (site name, method, seed, team size, and the
door-opening probability a laziness sweep varies) are set aside; everything else must be the same in
every trial, and is written once. A value that differs between trials (which would make the trials
incomparable) is listed under ``differs`` with the values seen, rather than hidden. A point sweep's
factors vary by design (:func:`varied_paths`): they are listed under ``varied_per_trial`` instead.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

PER_TRIAL = ("site", "method", "seed", "robots", "objects", "human_doors")  # top-level params of one trial
VARIED_HUMAN = ("door_probability", "task_mean", "interruption_cost")  # what the sweeps vary (CSV columns)


def _flatten(data: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for name, value in data.items():
        path = f"{prefix}{name}"
        if isinstance(value, dict):
            flat.update(_flatten(value, path + "."))
        else:
            flat[path] = value
    return flat


def varied_paths(factors: Iterable[str]) -> tuple[str, ...]:
    """Where a point sweep's factors show in the sim's params (``human.<field>``, ``site_params.<field>``)."""
    from .factors import FACTORS

    paths = []
    for name in factors:
        f = FACTORS.get(name)
        if f is not None and f.target in ("human", "site"):
            paths.append(f"{'human' if f.target == 'human' else 'site_params'}.{f.option}")
    return tuple(paths)


def model_params(metrics: Iterable[dict[str, Any]], varied: Iterable[str] = ()) -> dict[str, Any]:
    """The shared parameters of the trials whose ``metrics`` are given (see the module docstring);
    ``varied``: further parameter paths that vary by design (:func:`varied_paths`)."""
    by_design = set(varied)
    first: dict[str, Any] | None = None
    seen: dict[str, list[Any]] = {}
    varied: dict[str, set[Any]] = {name: set() for name in VARIED_HUMAN}
    count = 0
    for m in metrics:
        params = dict(m.get("params") or {})
        human = dict(params.get("human") or {})
        for name in VARIED_HUMAN:
            if name in human:
                varied[name].add(human.pop(name))
        params["human"] = human
        for name in PER_TRIAL:
            params.pop(name, None)
        count += 1
        if first is None:
            first = params
        for path, value in _flatten(params).items():
            values = seen.setdefault(path, [])
            if value not in values:
                values.append(value)
    if first is None:
        return {}
    differs = {path: values for path, values in seen.items() if len(values) > 1 and path not in by_design}
    out: dict[str, Any] = {
        "source": f"the simulator's metrics (params) of {count} finished trial(s)",
        **first,
        "varied_per_trial": {name: sorted(values) for name, values in varied.items()}
        | {path: sorted(seen[path]) for path in sorted(by_design) if path in seen},
        "per_trial": list(PER_TRIAL),
    }
    if differs:
        out["differs"] = differs
    return out


def write_params(path: Path, metrics: Iterable[dict[str, Any]], varied: Iterable[str] = ()) -> dict[str, Any]:
    data = model_params(metrics, varied)
    path.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    return data
