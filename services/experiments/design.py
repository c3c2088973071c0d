"""What a sweep is: its conditions, its trials, and the seeds each trial gets.

A sweep varies the number of robots (``robots``), the human's door-opening probability
(``laziness``), or her task length and the cost of an interruption together (``map``), across the
methods, with ``trials`` repetitions per condition. Everything a trial does follows from its
:class:`TrialKey` and the sweep's base seed, so the same sweep always runs the same trials.

The design is **paired** (common random numbers): for one trial index, every method meets

- the same **site** (building, robot starts, object places), from ``(seed, robots, objects, trial)``;
- the same **human**: the simulation seed comes from ``(seed, robots, objects, trial)`` too, and the
  simulator draws her task time, her focus intervals and each of her decisions from streams keyed by
  what they are for (``services/sim/streams.py``), not by the order things happen in. The method,
  the door-opening probability, the task length and the interruption cost are left out of the seed
  on purpose: two conditions differ only in what the condition changes, so a difference between two
  methods is measured on the same draws, trial by trial.

Seeds are the first four bytes of a SHA-256 of those values as text, so they do not depend on
Python's hash randomisation, the platform or the order trials happen to run in.
"""

from __future__ import annotations

import hashlib
from dataclasses import asdict, dataclass, field
from typing import Any

SWEEPS = ("robots", "laziness", "map")
METHODS = ("arroch", "no-feedback", "no-comm")  # the sim's --method values, the paper's order
SEED_MASK = 0x7FFFFFFF  # non-negative 31-bit: fits every seed argument down the line
DEFAULT_TASK = 600.0  # s: the simulator's default mean task length (services/sim/human.py, HumanConfig)
DEFAULT_COST = 0.0  # s: the simulator's default interruption cost (idem)
DEFAULT_P = 0.5  # the simulator's default door-opening probability (idem)
FOCUS_READINGS = ("faithful", "strict")  # the simulator's --focus-reading values (idem)


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

    def ident(self) -> str:
        """A file-name-safe id, e.g. ``arroch-n3-o3-p0.5-w600-c0-t07``."""
        return (
            f"{self.method}-n{self.robots}-o{self.objects}-p{format_p(self.p)}-w{format_p(self.task)}"
            f"-c{format_p(self.cost)}-t{self.trial:02d}"
        )

    def pair(self) -> tuple[int, int, float, float, float, int]:
        """What pairs this trial with the other methods' (everything but the method)."""
        return (self.robots, self.objects, self.p, self.task, self.cost, self.trial)


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
        if problems:
            raise ValueError("; ".join(problems))

    # ------------------------------------------------------------------ trials

    def conditions(self) -> list[tuple[str, int, float, float, float]]:
        """(method, robots, p, task, cost) in report order: the swept variables, then the methods."""
        return [
            (m, n, p, w, c)
            for n in self.robots
            for p in self.ps
            for w in self.tasks
            for c in self.costs
            for m in self.methods
        ]

    def keys(self) -> list[TrialKey]:
        """Every trial, in the CSV's order (condition by condition, trial index last)."""
        return [
            TrialKey(m, n, self.objects, p, w, c, i)
            for (m, n, p, w, c) in self.conditions()
            for i in range(self.trials)
        ]

    def schedule(self) -> list[TrialKey]:
        """Every trial, in the order to run them: repetition by repetition, so that at any moment
        every condition has about as many trials done (early results and the time estimate are
        representative, and an interrupted sweep is balanced)."""
        order = {cond: i for i, cond in enumerate(self.conditions())}
        return sorted(self.keys(), key=lambda k: (k.trial, order[(k.method, k.robots, k.p, k.task, k.cost)]))

    def site_seed(self, key: TrialKey) -> int:
        return derive_seed(self.seed, "site", key.robots, key.objects, key.trial)

    def sim_seed(self, key: TrialKey) -> int:
        """The human's seed: the same for every method and every human parameter (module docstring)."""
        return derive_seed(self.seed, "human", key.robots, key.objects, key.trial)

    def trial_count(self) -> int:
        return len(self.methods) * len(self.robots) * len(self.ps) * len(self.tasks) * len(self.costs) * self.trials

    # ------------------------------------------------------------------ persistence

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        for name in ("methods", "robots", "ps", "tasks", "costs"):
            data[name] = list(data[name])
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
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"not a sweep description ({exc})") from None

    def differences(self, other: SweepSpec) -> list[str]:
        """What differs from ``other``, one ``name: ours vs theirs`` per field (empty when equal)."""
        mine, theirs = self.to_json(), other.to_json()
        return [f"{name}: {theirs[name]!r} vs {mine[name]!r}" for name in mine if mine[name] != theirs[name]]
