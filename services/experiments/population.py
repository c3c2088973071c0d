"""A population of simulated people: each person's parameters drawn from stated distributions.

``--population FILE`` is a TOML file with any of

- ``[human]``: values every person shares (the human model's fields, as ``--human-config`` takes
  them; what ``arroch study calibrate`` writes as its point estimates);
- ``[calibration.<factor>]`` with ``estimate``, ``interval = [low, high]`` (95 %) and ``n``: what the
  calibration writes. Read as a prior: a person's value is drawn from a normal distribution centred
  on the estimate whose 95 % range is the interval (sd = (high − low) / 3.92), kept inside the
  factor's legal range (drawn again, up to 100 times, then clipped). The interval is the calibration's
  uncertainty about the typical person; it is used as the spread between persons because the
  calibration measures no other (a study of n people whose values really differ would show a
  between-person spread about √n times wider: the population here is, if anything, too alike).
- ``[population.<factor>]`` with ``distribution`` and its parameters: a stated prior, which wins over
  a calibration table of the same factor: ``normal`` (``mean``, ``sd``), ``uniform`` (``low``,
  ``high``), ``beta`` (``a``, ``b``, optionally scaled to [``low``, ``high``]), ``fixed``
  (``value``). Truncated to the factor's legal range as above.

The factors are :mod:`.factors`'s (the human model's parameters, the door hold, the capacity, ...).
A calibration table of a factor this sweep does not know is listed as unused, not silently dropped.

Draws: person ``i``'s value of factor ``f`` comes from a generator seeded by ``(seed, "person", i,
f)`` alone, so adding a factor or a person changes no other draw.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .design import derive_seed
from .factors import FACTORS, factor

DISTRIBUTIONS = ("normal", "uniform", "beta", "fixed")
Z_975 = 1.959964  # the 95 % interval is ±1.96 sd of a normal
REDRAWS = 100


@dataclass(frozen=True)
class Prior:
    factor: str
    distribution: str
    params: dict[str, float]
    source: str  # "calibration (estimate 0.42, 95 % interval [0.31, 0.55], n = 48)" or "stated prior"

    def draw(self, rng: np.random.Generator) -> float:
        f = factor(self.factor)
        low, high = f.limits
        for _ in range(REDRAWS):
            value = self._sample(rng)
            if low <= value <= high:
                return f.clip(value)
        return f.clip(value)

    def _sample(self, rng: np.random.Generator) -> float:
        p = self.params
        if self.distribution == "normal":
            return float(rng.normal(p["mean"], p["sd"]))
        if self.distribution == "uniform":
            return float(rng.uniform(p["low"], p["high"]))
        if self.distribution == "beta":
            unit = float(rng.beta(p["a"], p["b"]))
            return p.get("low", 0.0) + unit * (p.get("high", 1.0) - p.get("low", 0.0))
        return float(p["value"])

    def describe(self) -> str:
        shown = ", ".join(f"{k} = {v:g}" for k, v in self.params.items())
        return f"{self.factor}: {self.distribution}({shown}), from {self.source}"


@dataclass
class Population:
    human: dict[str, Any]  # the [human] table but its trial-key factors: shared by every person
    priors: list[Prior] = field(default_factory=list)
    unused: list[str] = field(default_factory=list)  # calibration tables of unknown factors
    fixed: dict[str, float] = field(default_factory=dict)  # [human] values that are trial-key factors

    def persons(self, count: int, seed: int) -> tuple[dict[str, float], ...]:
        """``count`` persons' drawn factors (module docstring)."""
        people = []
        for i in range(count):
            person = dict(self.fixed)
            for prior in self.priors:
                rng = np.random.default_rng(derive_seed(seed, "person", i, prior.factor))
                person[prior.factor] = prior.draw(rng)
            people.append(person)
        return tuple(people)


def _number(table: dict[str, Any], name: str, where: str) -> float:
    value = table.get(name)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{where}: {name} must be a number (got {value!r})")
    return float(value)


def _stated(name: str, table: dict[str, Any], where: str) -> Prior:
    kind = table.get("distribution")
    if kind not in DISTRIBUTIONS:
        raise ValueError(f"{where}: distribution must be one of {', '.join(DISTRIBUTIONS)} (got {kind!r})")
    needs = {"normal": ("mean", "sd"), "uniform": ("low", "high"), "beta": ("a", "b"), "fixed": ("value",)}[kind]
    params = {n: _number(table, n, where) for n in needs}
    params.update({n: _number(table, n, where) for n in ("low", "high") if kind == "beta" and n in table})
    if kind == "normal" and params["sd"] < 0 or kind == "uniform" and params["low"] > params["high"]:
        raise ValueError(f"{where}: {params} is not a distribution")
    if kind == "beta" and (params["a"] <= 0 or params["b"] <= 0):
        raise ValueError(f"{where}: beta needs a > 0 and b > 0")
    return Prior(name, kind, params, "a stated prior")


def _calibrated(name: str, table: dict[str, Any], where: str) -> Prior:
    estimate = _number(table, "estimate", where)
    interval = table.get("interval")
    if not (isinstance(interval, list) and len(interval) == 2):
        raise ValueError(f"{where}: interval must be [low, high] (got {interval!r})")
    low, high = (_number({"v": v}, "v", f"{where}.interval") for v in interval)
    if not low <= estimate <= high:
        raise ValueError(f"{where}: the estimate {estimate:g} is outside its interval [{low:g}, {high:g}]")
    n = table.get("n", "?")
    source = f"the calibration (estimate {estimate:g}, 95 % interval [{low:g}, {high:g}], n = {n})"
    return Prior(name, "normal", {"mean": estimate, "sd": (high - low) / (2 * Z_975)}, source)


def load_population(path: Path) -> Population:
    """The population FILE (module docstring); raises ValueError naming what is wrong."""
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise ValueError(f"--population {path}: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"--population {path}: {exc}") from None
    human = {k: v for k, v in (data.get("human") or {}).items() if not isinstance(v, dict)}
    fixed = {k: float(v) for k, v in human.items() if k in FACTORS and FACTORS[k].target == "key"}
    priors: dict[str, Prior] = {}
    unused = []
    for name, table in sorted((data.get("calibration") or {}).items()):
        if not isinstance(table, dict) or "interval" not in table:
            continue
        if name not in FACTORS:
            unused.append(name)
            continue
        priors[name] = _calibrated(name, table, f"{path}: calibration.{name}")
    for name, table in sorted((data.get("population") or {}).items()):
        if name not in FACTORS:
            raise ValueError(f"{path}: population.{name}: unknown factor (known: {', '.join(FACTORS)})")
        priors[name] = _stated(name, dict(table), f"{path}: population.{name}")
    if not priors:
        raise ValueError(f"{path}: no [population.<factor>] prior and no [calibration.<factor>] interval to draw from")
    shared = {k: v for k, v in human.items() if k not in fixed}
    return Population(shared, list(priors.values()), unused, fixed)
