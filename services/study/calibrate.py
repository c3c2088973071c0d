"""``arroch study calibrate DIR``: fit the simulated human's parameters to what the participants did.

Reads every complete trial's log.jsonl (and metrics.json for the timestamps' resolution), fits the
parameters :mod:`.fits` describes, and writes a human config (default ``DIR/human.toml``):

- ``[human]``: every parameter of the simulated human (services/sim/human.py ``HumanConfig``), the
  fitted ones where identified and the base config's value otherwise. ``arroch sim --human-config``
  reads this table, and refuses any key that is not a parameter, so nothing else goes there;
- ``[calibration]``: the study, the trials used and left out, the base config;
- ``[calibration.<param>]`` for every parameter: for a fitted one its estimate, 95 % interval, n,
  method, whether it is identified (and the minimum for that) and the value written; for one not
  fitted, why not.

The base config (``--base-config FILE``, its ``[human]`` table or top-level keys) supplies what is
not fitted or not identified, and ``decision_interval`` and ``declare_probability``, which the fits
of door_probability and focus_count are conditional on. Without it, the simulator's defaults
(``HUMAN_DEFAULTS``, kept equal to ``HumanConfig``'s by a test).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tomllib
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .layout import StudyError, StudyFolder
from .trialdata import TrialData, load_trials

if TYPE_CHECKING:
    from .fits import Fit

# The fits (scipy) are imported when a calibration runs, not whenever `arroch study` starts.

#: The simulated human's parameters and defaults (services/sim/human.py HumanConfig; a test keeps them equal).
HUMAN_DEFAULTS: dict[str, Any] = {
    "task_mean": 600.0,
    "task_std": 60.0,
    "task_min": 60.0,
    "walk_speed": 1.0,
    "open_time": 3.0,
    "declare_time": 1.0,
    "door_probability": 0.5,
    "decision_interval": 10.0,
    "no_comm_probability": 0.6,
    "no_comm_interval": 60.0,
    "focus_count": 2,
    "focus_min_minutes": 2,
    "focus_max_minutes": 4,
    "declare_probability": 0.9,
    "focus_reading": "faithful",
    "interruption_cost": 0.0,
    "feedback_timeout": 2.0,
    "feedback_retries": 3,
    "anticipation": 0.0,
    "focus_responsiveness": 1.0,
    "focus_fraction": 0.0,
}
DEFAULT_RESOLUTION = 0.05  # s: the simulator's default tick, when no metrics record one

#: Why each parameter that is not fitted is not.
NOT_FITTED = {
    "task_min": "a floor on the Gaussian draw so no draw is absurd, not a behaviour: the base value is kept",
    "walk_speed": "fixed by the virtual world (the simulator walks her avatar), not measured: the base value is kept",
    "open_time": "fixed by the virtual world's page (the press-and-hold lasts what the simulator sets), not measured",
    "decision_interval": "kept at its configured value: door_probability is the chance per decision on this grid",
    "no_comm_probability": "no study condition hides the robots from her (No-comm is not a study condition)",
    "no_comm_interval": "no study condition hides the robots from her (No-comm is not a study condition)",
    "declare_probability": (
        "not identifiable from declarations alone: an undeclared focus interval leaves no trace in the log. "
        "The base value (the paper's 0.9 by default) is kept, and focus_count is fitted given it"
    ),
    "focus_reading": "a reading of the model (which focus intervals keep her from doors), not a measurement",
    "feedback_timeout": "the simulator's messaging, not her behaviour",
    "feedback_retries": "the simulator's messaging, not her behaviour",
    "anticipation": (
        "not fitted: it would need what the AR view showed her of the robots' plans at each moment, which the "
        "log does not hold; her trips with no robot waiting are counted (door_probability's note) but not "
        "attributed. The base value is kept"
    ),
    "focus_responsiveness": (
        "not identifiable: how she answers robots during a focus interval she did not declare needs those "
        "intervals, and an undeclared interval leaves no trace in the log. The base value is kept"
    ),
    "focus_fraction": (
        "not fitted: the declared minutes give whole-minute lengths (focus_min_minutes..focus_max_minutes). When "
        "those are identified 0 is written so the simulator draws them; otherwise the base value is kept"
    ),
}


# ---------------------------------------------------------------------------- base config


def read_base(path: Path | None) -> dict[str, Any]:
    """The base parameters: HUMAN_DEFAULTS overlaid with the file's ``[human]`` (or top-level) keys."""
    base = dict(HUMAN_DEFAULTS)
    if path is None:
        return base
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise StudyError(f"base config {path} does not exist") from None
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"base config {path}: not valid TOML: {exc}") from None
    table = data.get("human", data)
    if not isinstance(table, dict):
        raise StudyError(f"base config {path}: [human] should be a table")
    for key, value in table.items():
        if key not in HUMAN_DEFAULTS:
            raise StudyError(f"base config {path}: [human] has an unknown key {key!r}")
        default = HUMAN_DEFAULTS[key]
        if isinstance(default, str):
            ok = isinstance(value, str)
        elif isinstance(default, int) and not isinstance(default, bool):
            ok = isinstance(value, int) and not isinstance(value, bool)
        else:
            ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
        if not ok:
            raise StudyError(f"base config {path}: [human] {key} = {value!r} is not a {type(default).__name__}")
        base[key] = float(value) if isinstance(default, float) else value
    return base


# ---------------------------------------------------------------------------- fitting


def calibrate(trials: list[TrialData], base: dict[str, Any]) -> tuple[dict[str, Fit], float]:
    """The fits from the complete trials that have a log, and the timestamps' resolution used."""
    from .fits import (
        fit_declare_time,
        fit_door_probability,
        fit_focus_count,
        fit_focus_minutes,
        fit_interruption,
        fit_task,
        time_resolution,
    )

    used = [t for t in trials if t.complete and t.has_log]
    resolution = time_resolution([t.metrics for t in used], DEFAULT_RESOLUTION)
    timelines = [t.timeline() for t in used]
    arroch = [t.timeline() for t in used if t.condition == "arroch"]
    fits: dict[str, Fit] = {}
    fits["door_probability"] = fit_door_probability(
        [(t.condition, t.timeline()) for t in used], base["decision_interval"], base["door_probability"]
    )
    fits["declare_time"] = fit_declare_time(timelines, resolution, base["declare_time"])
    fmin, fmax = fit_focus_minutes(arroch, (base["focus_min_minutes"], base["focus_max_minutes"]))
    fits[fmin.param], fits[fmax.param] = fmin, fmax
    fits["interruption_cost"] = fit_interruption(timelines, resolution, base["interruption_cost"])
    cost = written_value(fits["interruption_cost"], base)
    fits["task_mean"], fits["task_std"] = fit_task(timelines, cost, (base["task_mean"], base["task_std"]))
    # focus_count goes through the model's rule for keeping intervals, with the values written above.
    human = human_table(fits, base)
    fits["focus_count"] = fit_focus_count(
        arroch,
        base["declare_probability"],
        (human["task_mean"], human["task_std"], human["task_min"]),
        (human["focus_min_minutes"], human["focus_max_minutes"]),
        base["focus_count"],
    )
    return fits, resolution


def written_value(fit: Fit, base: dict[str, Any]) -> Any:
    """What goes into [human]: the estimate when identified, else the base value."""
    if not fit.identified or fit.estimate is None:
        return base[fit.param]
    default = HUMAN_DEFAULTS[fit.param]
    if isinstance(default, int) and not isinstance(default, bool):
        return int(fit.estimate)
    value = float(fit.estimate)
    if fit.param == "door_probability":
        return min(1.0, max(0.0, round(value, 6)))
    return max(0.0, round(value, 6))


def human_table(fits: dict[str, Fit], base: dict[str, Any]) -> dict[str, Any]:
    human = dict(base)
    for name, fit in fits.items():
        human[name] = written_value(fit, base)
    if fits.get("focus_min_minutes") is not None and fits["focus_min_minutes"].identified:
        human["focus_fraction"] = 0.0  # the fitted whole-minute lengths are what the simulator should draw
    if human["focus_min_minutes"] > human["focus_max_minutes"]:  # one bound fitted, the other not
        human["focus_min_minutes"] = human["focus_max_minutes"] = human["focus_min_minutes"]
    if human["task_mean"] <= 0:
        human["task_mean"] = base["task_mean"]
    return human


# ---------------------------------------------------------------------------- the file


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            raise ValueError("no NaN is written: an undefined value is left out")
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"  # TOML's infinity: an open bound
        return repr(round(value, 6))
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # a TOML basic string: JSON's escapes are TOML's
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{json.dumps(str(k))} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def _table(name: str, values: dict[str, Any]) -> list[str]:
    lines = [f"[{name}]"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in values.items() if v is not None]
    return [*lines, ""]


def calibration_toml(
    *,
    study: str,
    folder: Path,
    fits: dict[str, Fit],
    base: dict[str, Any],
    base_source: str,
    trials: list[TrialData],
    resolution: float,
) -> str:
    human = human_table(fits, base)
    used = [t for t in trials if t.complete and t.has_log]
    left_out = [f"{t.trial}: {t.reason or 'no log.jsonl'}" for t in trials if not (t.complete and t.has_log)]
    lines = [
        f"# The simulated human calibrated from study {study!r} ({folder}) by `arroch study calibrate`.",
        "# [human] is what `arroch sim --human-config` reads; [calibration.*] says where each value comes from.",
        "",
        *_table("human", human),
        *_table(
            "calibration",
            {
                "study": study,
                "created": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
                "trials_used": len(used),
                "trials_left_out": left_out,
                "base": base_source,
                "time_resolution_s": resolution,
            },
        ),
    ]
    for name in HUMAN_DEFAULTS:
        fit = fits.get(name)
        if fit is None:
            lines += _table(f"calibration.{name}", {"fitted": False, "why": NOT_FITTED[name], "written": human[name]})
            continue
        note = fit.note
        if not fit.identified:
            note = f"not identified (n = {fit.n}; needs {fit.minimum}): the base value {base[name]!r} is kept. " + note
        values: dict[str, Any] = {
            "fitted": True,
            "identified": fit.identified,
            "estimate": fit.estimate,
            "interval": [fit.low, fit.high] if fit.low is not None and fit.high is not None else None,
            "n": fit.n,
            "minimum": fit.minimum,
            "method": fit.method,
            "note": note,
            "written": human[name],
        }
        values.update({k: v for k, v in fit.extra.items() if v is not None})
        lines += _table(f"calibration.{name}", values)
    return "\n".join(lines)


def summary(fits: dict[str, Fit], human: dict[str, Any]) -> str:
    head = ["parameter", "estimate", "95 % interval", "n", "identified", "written"]
    rows = [head]
    for name, fit in fits.items():
        interval = f"[{fit.low:.4g}, {fit.high:.4g}]" if fit.low is not None and fit.high is not None else "-"
        est = f"{round(fit.estimate, 6):.4g}" if isinstance(fit.estimate, float) else str(fit.estimate)
        rows.append([name, est, interval, str(fit.n), "yes" if fit.identified else "no", str(human[name])])
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows)


# ---------------------------------------------------------------------------- the command


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dir", metavar="DIR", help="the study folder")
    parser.add_argument("--out", metavar="FILE", help="the human config to write (default DIR/human.toml)")
    parser.add_argument(
        "--base-config",
        metavar="FILE",
        help="human config whose values are kept where nothing is fitted (default: the simulator's defaults)",
    )


def main(args: argparse.Namespace) -> int:
    folder = StudyFolder(args.dir)
    out = Path(args.out) if args.out else folder.human_config
    try:
        plan = folder.plan()
        base_path = Path(args.base_config) if args.base_config else None
        base = read_base(base_path)
        trials = load_trials(folder, plan)
        fits, resolution = calibrate(trials, base)
        text = calibration_toml(
            study=plan.name,
            folder=folder.root,
            fits=fits,
            base=base,
            base_source=str(base_path) if base_path else "the simulator's defaults (HumanConfig)",
            trials=trials,
            resolution=resolution,
        )
    except StudyError as exc:
        print(f"arroch study calibrate: {exc}", file=sys.stderr)
        return 2
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(out)
    used = sum(1 for t in trials if t.complete and t.has_log)
    print(f"{used} of {len(trials)} trials used")
    print(summary(fits, human_table(fits, base)))
    print(f"human config written to {out}  (arroch sim --human-config {out})")
    return 0
