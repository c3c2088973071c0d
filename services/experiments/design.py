"""What a sweep is: its conditions, its trials, and the seeds each trial gets.

A sweep varies the number of robots (``robots``), the human's door-opening probability
(``laziness``), or her task length and the cost of an interruption together (``map``), across the
methods, with ``trials`` repetitions per condition. Everything a trial does follows from its
:class:`TrialKey` and the sweep's base seed, so the same sweep always runs the same trials.

The *point* sweeps (``detour``, ``sensitivity``, ``population``) vary instead a table of
**points** (``SweepSpec.points``): each point a mapping of factors to values (:mod:`.factors`:
the robots' capacity, the door hold, the share of deliveries behind her door, and any of the
human model's parameters), each trial a point, a method and a repetition (``TrialKey.point``).
``detour`` crosses capacities and door shares on the detour buildings
(:mod:`runtime.site.generate_detour`); ``sensitivity`` runs the samples of a Morris or Sobol
design (:mod:`.sensitivity`); ``population`` runs one point per simulated person
(:mod:`.population`). ``domain`` says which buildings: ``paper`` (every delivery through her door,
``generate_site``) or ``detour``. ``human`` sets human-model parameters for every trial of any
sweep (``--anticipation``, ``--focus-fraction``, ``--focus-responsiveness``); empty, the trials
run exactly as before these options existed.

The design is **paired** (common random numbers): for one trial index, every method meets

- the same **site** (building, robot starts, object places), from ``(seed, robots, objects, trial)``;
- the same **human**: the simulation seed comes from ``(seed, robots, objects, trial)`` too, and the
  simulator draws her task time, her focus intervals and each of her decisions from streams keyed by
  what they are for (``services/sim/streams.py``), not by the order things happen in. The method,
  the door-opening probability, the task length and the interruption cost are left out of the seed
  on purpose: two conditions differ only in what the condition changes, so a difference between two
  methods is measured on the same draws, trial by trial.

The point is left out of the seeds too (every point of a detour or sensitivity sweep meets the same
buildings and the same human draws: common random numbers across points, so an elementary effect
of the sensitivity analysis compares two settings on the same draws), except in a ``population``
sweep: there each person meets buildings and draws of her own (the seeds add ``person`` and the
point), so persons are independent samples, as the mixed model assumes.

Seeds are the first four bytes of a SHA-256 of those values as text, so they do not depend on
Python's hash randomisation, the platform or the order trials happen to run in.
"""

from __future__ import annotations

import hashlib
from dataclasses import asdict, dataclass, field
from typing import Any

from .factors import KEY_OPTIONS, check_point

SWEEPS = ("robots", "laziness", "map", "detour", "sensitivity", "population")
POINT_SWEEPS = ("detour", "sensitivity", "population")  # trials are points x methods x repetitions
DOMAINS = ("paper", "detour")  # generate_site (every delivery through her door) or generate_detour_site
METHODS = ("arroch", "no-feedback", "no-comm")  # the sim's --method values, the paper's order
SEED_MASK = 0x7FFFFFFF  # non-negative 31-bit: fits every seed argument down the line
DEFAULT_TASK = 600.0  # s: the simulator's default mean task length (services/sim/human.py, HumanConfig)
DEFAULT_COST = 0.0  # s: the simulator's default interruption cost (idem)
DEFAULT_P = 0.5  # the simulator's default door-opening probability (idem)
FOCUS_READINGS = ("faithful", "strict")  # the simulator's --focus-reading values (idem)
# The detour domain's share of deliveries behind her door when a sweep does not vary it: chosen, half of
# them (the paper's task is 1; at 0.5 every robot of three objects has errands both ways on average).
DEFAULT_DOOR_SHARE = 0.5


def derive_seed(*parts: object) -> int:
    """A stable seed from ``parts`` (their ``str`` joined by ``|``)."""
    digest = hashlib.sha256("|".join(str(p) for p in parts).encode("utf-8")).digest()
    return int.from_bytes(digest[:4], "big") & SEED_MASK


def format_p(p: float) -> str:
    """A door-opening probability (or any condition value) as it appears in CSV cells and labels
    (``0.05``, ``1``, ``600``)."""
    return f"{p:g}"


@dataclass(frozen=True, order=True)
class TrialKey:
    """One trial: a condition (method, team size, objects per robot, door-opening probability, the
    human's mean task length and interruption cost) and its repetition index. The CSV's identity
    columns are exactly these fields."""

    method: str
    robots: int
    objects: int
    p: float
    task: float
    cost: float
    trial: int
    point: int = -1  # the row of SweepSpec.points (point sweeps); -1: none

    def ident(self) -> str:
        """A file-name-safe id, e.g. ``arroch-n3-o3-p0.5-w600-c0-t07`` (``-x004`` added for point 4)."""
        return (
            f"{self.method}-n{self.robots}-o{self.objects}-p{format_p(self.p)}-w{format_p(self.task)}"
            f"-c{format_p(self.cost)}-t{self.trial:02d}" + (f"-x{self.point:03d}" if self.point >= 0 else "")
        )

    def pair(self) -> tuple[int, int, float, float, float, int, int]:
        """What pairs this trial with the other methods' (everything but the method)."""
        return (self.robots, self.objects, self.p, self.task, self.cost, self.trial, self.point)


@dataclass(frozen=True)
class SweepSpec:
    """The parameters that decide a sweep's results (and nothing that only decides its speed).

    ``human_config`` is the text of a ``--human-config`` TOML file, or ``None`` for the simulator's
    defaults (the paper's model): results are only comparable under the same model, so a resumed
    sweep must use the same text."""

    kind: str
    methods: tuple[str, ...]
    robots: tuple[int, ...]
    objects: int
    ps: tuple[float, ...]
    trials: int
    seed: int
    tasks: tuple[float, ...] = (DEFAULT_TASK,)  # the human's mean task length (s), the sim's --task-mean
    costs: tuple[float, ...] = (DEFAULT_COST,)  # s of her task lost per interruption, the sim's --interruption-cost
    human_config: str | None = None
    focus_reading: str | None = None  # the sim's --focus-reading (faithful or strict); None: its default (faithful)
    time_limit: float | None = None  # the sim's --time-limit (sim seconds); None: its default
    extra: dict[str, Any] = field(default_factory=dict)
    human: dict[str, Any] = field(default_factory=dict)  # human-model fields for every trial (module docstring)
    points: tuple[dict[str, float], ...] = ()  # point sweeps: factor -> value, one per point
    domain: str = "paper"  # the buildings: paper (generate_site) or detour (generate_detour_site)

    def __post_init__(self) -> None:
        problems = []
        if self.kind not in SWEEPS:
            problems.append(f"sweep kind must be one of {', '.join(SWEEPS)}, got {self.kind!r}")
        unknown = [m for m in self.methods if m not in METHODS]
        if unknown or not self.methods:
            problems.append(f"methods must be among {', '.join(METHODS)} (got {', '.join(self.methods) or 'none'})")
        if len(set(self.methods)) != len(self.methods):
            problems.append("a method is listed twice")
        if not self.robots or any(n < 1 for n in self.robots) or len(set(self.robots)) != len(self.robots):
            problems.append(f"robots must be distinct integers >= 1 (got {list(self.robots)})")
        if self.objects < 1:
            problems.append(f"objects per robot must be >= 1 (got {self.objects})")
        if not self.ps or any(not 0.0 <= p <= 1.0 for p in self.ps) or len(set(self.ps)) != len(self.ps):
            problems.append(f"door-opening probabilities must be distinct values in [0, 1] (got {list(self.ps)})")
        if self.trials < 1:
            problems.append(f"trials must be >= 1 (got {self.trials})")
        if not 0 <= self.seed <= SEED_MASK:
            problems.append(f"seed must be within [0, {SEED_MASK}] (got {self.seed})")
        if not self.tasks or any(not t > 0 for t in self.tasks) or len(set(self.tasks)) != len(self.tasks):
            problems.append(f"task lengths must be distinct values > 0 s (got {list(self.tasks)})")
        if not self.costs or any(not c >= 0 for c in self.costs) or len(set(self.costs)) != len(self.costs):
            problems.append(f"interruption costs must be distinct values >= 0 s (got {list(self.costs)})")
        if self.focus_reading not in (None, *FOCUS_READINGS):
            problems.append(f"focus reading must be one of {', '.join(FOCUS_READINGS)} (got {self.focus_reading!r})")
        if self.time_limit is not None and not self.time_limit > 0:
            problems.append(f"time limit must be > 0 sim seconds (got {self.time_limit})")
        if self.domain not in DOMAINS:
            problems.append(f"domain must be one of {', '.join(DOMAINS)} (got {self.domain!r})")
        if (self.kind in POINT_SWEEPS) != bool(self.points):
            problems.append(f"a {self.kind} sweep {'needs' if self.kind in POINT_SWEEPS else 'takes no'} points")
        if self.kind in POINT_SWEEPS and (len(self.robots) != 1 or len(self.ps) != 1):
            problems.append("a point sweep has one team size and one door-opening probability (points vary the rest)")
        for i, point in enumerate(self.points):
            problems += [f"point {i}: {problem}" for problem in check_point(point)]
        if problems:
            raise ValueError("; ".join(problems))

    # ------------------------------------------------------------------ trials

    def conditions(self) -> list[tuple[str, int, float, float, float, int]]:
        """(method, robots, p, task, cost, point) in report order: the swept variables, then the methods."""
        if self.points:
            return [(m, *self._point_key(i), i) for i in range(len(self.points)) for m in self.methods]
        return [
            (m, n, p, w, c, -1)
            for n in self.robots
            for p in self.ps
            for w in self.tasks
            for c in self.costs
            for m in self.methods
        ]

    def _point_key(self, index: int) -> tuple[int, float, float, float]:
        """(robots, p, task, cost) of point ``index``: its own values where it sets them."""
        point = self.points[index]
        values = {"door_probability": self.ps[0], "task_mean": self.tasks[0], "interruption_cost": self.costs[0]}
        values.update({name: float(point[name]) for name in KEY_OPTIONS if name in point})
        return (self.robots[0], values["door_probability"], values["task_mean"], values["interruption_cost"])

    def keys(self) -> list[TrialKey]:
        """Every trial, in the CSV's order (condition by condition, trial index last)."""
        return [
            TrialKey(m, n, self.objects, p, w, c, i, x)
            for (m, n, p, w, c, x) in self.conditions()
            for i in range(self.trials)
        ]

    def schedule(self) -> list[TrialKey]:
        """Every trial, in the order to run them: repetition by repetition, so that at any moment
        every condition has about as many trials done (early results and the time estimate are
        representative, and an interrupted sweep is balanced)."""
        order = {cond: i for i, cond in enumerate(self.conditions())}
        return sorted(self.keys(), key=lambda k: (k.trial, order[(k.method, k.robots, k.p, k.task, k.cost, k.point)]))

    def point(self, key: TrialKey) -> dict[str, float]:
        """The factors of ``key``'s point (empty outside point sweeps)."""
        return dict(self.points[key.point]) if key.point >= 0 else {}

    def factor_names(self) -> tuple[str, ...]:
        """Every factor some point sets, but those the trial key already has a column for (sorted)."""
        return tuple(sorted({name for point in self.points for name in point} - set(KEY_OPTIONS)))

    def _own_draws(self, key: TrialKey) -> tuple[object, ...]:
        """A population's persons meet draws of their own; everyone else shares them (module docstring)."""
        return ("person", key.point) if self.kind == "population" else ()

    def site_seed(self, key: TrialKey) -> int:
        return derive_seed(self.seed, "site", key.robots, key.objects, key.trial, *self._own_draws(key))

    def sim_seed(self, key: TrialKey) -> int:
        """The human's seed: the same for every method and every human parameter (module docstring)."""
        return derive_seed(self.seed, "human", key.robots, key.objects, key.trial, *self._own_draws(key))

    def trial_count(self) -> int:
        if self.points:
            return len(self.methods) * len(self.points) * self.trials
        return len(self.methods) * len(self.robots) * len(self.ps) * len(self.tasks) * len(self.costs) * self.trials

    # ------------------------------------------------------------------ persistence

    def to_json(self) -> dict[str, Any]:
        """The spec as JSON data; the fields added with the point sweeps only when they are set, so a
        sweep of the earlier kinds writes the same sweep.json as before them."""
        data = asdict(self)
        for name in ("methods", "robots", "ps", "tasks", "costs", "points"):
            data[name] = list(data[name])
        for name, unset in (("human", {}), ("points", []), ("domain", "paper")):
            if data[name] == unset:
                del data[name]
        return data

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> SweepSpec:
        try:
            return cls(
                kind=data["kind"],
                methods=tuple(data["methods"]),
                robots=tuple(int(n) for n in data["robots"]),
                objects=int(data["objects"]),
                ps=tuple(float(p) for p in data["ps"]),
                trials=int(data["trials"]),
                seed=int(data["seed"]),
                tasks=tuple(float(t) for t in data.get("tasks", (DEFAULT_TASK,))),
                costs=tuple(float(c) for c in data.get("costs", (DEFAULT_COST,))),
                human_config=data.get("human_config"),
                focus_reading=data.get("focus_reading"),
                time_limit=data.get("time_limit"),
                extra=dict(data.get("extra") or {}),
                human=dict(data.get("human") or {}),
                points=tuple(dict(p) for p in data.get("points") or ()),
                domain=data.get("domain", "paper"),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"not a sweep description ({exc})") from None

    def differences(self, other: SweepSpec) -> list[str]:
        """What differs from ``other``, one ``name: ours vs theirs`` per field (empty when equal)."""
        mine, theirs = self.to_json(), other.to_json()
        return [
            f"{name}: {theirs.get(name)!r} vs {mine.get(name)!r}"
            for name in [*mine, *(n for n in theirs if n not in mine)]
            if mine.get(name) != theirs.get(name)
        ]
