"""The estimators behind ``arroch study calibrate``: the simulated human's parameters (the rules of
services/sim/human.py, restated here because services do not import one another) measured from
what participants did.

Each estimator takes the timelines of the trials it is about and returns a :class:`Fit`: the
estimate, its 95 % interval, how many observations it rests on, the method, and whether that is
enough to call it identified (``n`` at least the stated minimum). Timestamps are known only to the
log's resolution (the simulator's tick for the records it stamps), so an interval on seconds is
never narrower than that resolution on either side.

- **door_probability** (her response to a waiting robot). The model: each robot waiting at her door
  is one independent chance per ``decision_interval`` — the first when it starts waiting
  (Event ``waiting_at_door``), then every interval while it still waits — taken only while she is
  at her desk, the door is shut and no declared focus window of hers runs (a declaration stops
  deciding until her task is done). From the log: a robot's waiting episode runs from its
  ``waiting_at_door`` to the door opening (Event ``door_opened``), any other Event about that
  robot, or the trial's end; its decision times are ``start + k * decision_interval`` before the
  episode ends. Each ``go_to_door`` is credited to the latest decision time at or before it among
  the robots waiting at that door then (one success; when several robots' decisions fall at that
  same moment, the model takes them in robot order and stops once she goes, so only the first is
  counted); every other decision time at which the rule lets her decide is an opportunity she let
  pass. Her chance is taken to be the same inside an undeclared focus interval (the model's
  ``focus_responsiveness`` 1), since such intervals leave no trace. Episodes that end without her going (the door
  opened by an earlier trip, the robot left, the trial ended) are censored: their passed decision
  times count as failures, and nothing else. ``p = successes / opportunities``, Clopper-Pearson
  interval. The latency from an episode's start to the trip that answered it is reported as a
  distribution (quartiles), with the censored episodes counted.
- **declare_time**: the length of each view away from the puzzle that holds a declaration and no
  door trip; mean with its t interval.
- **focus_count**: declarations per ARROCH trial (Poisson rate, Garwood interval) divided by
  ``declare_probability`` (the model declares a focus interval with that chance and otherwise leaves
  no trace) is the number of focus intervals she has per trial. The model draws ``focus_count``
  intervals but drops the last while they sum to more than 90 % of her task time, so that number is
  matched to the model's mean kept (Monte Carlo over the fitted task time and minutes): the nearest
  integer, and the interval's ends mapped through the same curve.
- **focus_min_minutes / focus_max_minutes**: the smallest and largest minutes declared, each bound
  widened while a wider range (whole minutes drawn uniformly, as the model does) would still leave
  its extra values unseen with probability >= 2.5 %.
- **task_mean / task_std**: her active puzzle time to completion (at her desk in the puzzle view)
  less the interruption cost of each trip she made before finishing; t interval for the mean,
  chi-square interval for the standard deviation; the puzzle rate (pieces per active minute) beside it.
- **interruption_cost**: the working time between the last puzzle move before a door trip and the
  first after it, less her usual working time between moves in that trial. The usual time is the
  length-biased mean ``sum(L^2) / sum(L)`` of her uninterrupted intervals: a trip falls in an interval
  with probability proportional to its length, so the interval a trip lands in is longer than a typical
  one even when the trip costs nothing. Mean with its t interval over intervals holding exactly one trip.
  Measured on every trip; the model charges it only to trips made during a focus interval.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .stats import NAN, Estimate, clopper_pearson, mean_ci, poisson_ci, quartiles, sd_ci
from .timeline import AVAILABLE_KIND, DECLARE_KIND, Span, Timeline, overlap, union

TOL = 1e-6  # s: times closer than this are the same instant (the model acts at tick ends)
# The least data an estimate is called identified on (below: the base config's value is kept).
MIN_OPPORTUNITIES = 30
MIN_SUCCESSES = 5
MIN_DECLARATION_TIMES = 5
MIN_ARROCH_TRIALS = 5
MIN_DECLARATIONS = 5
MIN_TASK_TRIALS = 5
MIN_INTERRUPTIONS = 5
UNSEEN_LEVEL = 0.025  # focus minutes: a bound is widened while unseen values this likely remain
MAX_FOCUS_COUNT = 20  # focus_count searched up to here
FOCUS_SEED = 20_261  # fixed: the same logs give the same focus_count, run after run


@dataclass
class Fit:
    param: str
    estimate: float | int | None
    low: float | None
    high: float | None
    n: int
    method: str
    identified: bool
    minimum: str  # the stated minimum for "identified"
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


def _finite(x: float) -> float | None:
    return None if x is None or math.isnan(x) else float(x)


def _floor(est: Estimate, resolution: float) -> tuple[float, float]:
    """The interval, at least ``resolution`` either side of the estimate (timestamps' resolution)."""
    low = est.low if not math.isnan(est.low) else est.value
    high = est.high if not math.isnan(est.high) else est.value
    return min(low, est.value - resolution), max(high, est.value + resolution)


# ---------------------------------------------------------------------------- door response


@dataclass(frozen=True)
class Episode:
    robot: str
    door: str
    start: float
    end: float


@dataclass
class ResponseCounts:
    successes: int = 0
    opportunities: int = 0
    latencies: list[float] = field(default_factory=list)
    answered: int = 0
    censored: int = 0
    unprompted: int = 0  # trips with no robot waiting at that door
    ties: int = 0  # trips when two or more robots' decisions fell at the same moment (see response_counts)

    def add(self, other: ResponseCounts) -> None:
        self.successes += other.successes
        self.opportunities += other.opportunities
        self.latencies += other.latencies
        self.answered += other.answered
        self.censored += other.censored
        self.unprompted += other.unprompted
        self.ties += other.ties


def episodes(tl: Timeline) -> list[Episode]:
    """Each robot's waiting episodes at a door she operates (module docstring)."""
    mine = set(tl.doors)
    open_: dict[str, tuple[str, float]] = {}  # robot -> (door, since)
    out: list[Episode] = []

    def close(robot: str, t: float) -> None:
        door, since = open_.pop(robot)
        out.append(Episode(robot, door, since, t))

    for ev in tl.events:
        if ev.kind == "waiting_at_door" and ev.robot:
            if ev.robot in open_:
                close(ev.robot, ev.t)
            if not mine or ev.door in mine:
                open_[ev.robot] = (ev.door, ev.t)
        elif ev.kind == "door_opened":
            for robot in [r for r, (d, _) in open_.items() if d == ev.door]:
                close(robot, ev.t)
        elif ev.robot in open_:
            close(ev.robot, ev.t)  # anything else about the robot: it is no longer just waiting
    for robot in list(open_):
        close(robot, max(open_[robot][1], tl.end))
    return sorted(out, key=lambda e: (e.start, e.robot))


def declared_windows(tl: Timeline) -> dict[str, list[Span]]:
    """Per door, when a declaration of hers keeps her from deciding (ends early at her
    ``door_available_now`` on that door, and at her task done)."""
    out: dict[str, list[Span]] = {}
    stop = tl.work_end
    for act in tl.feedback:
        if act.kind != DECLARE_KIND or act.minutes <= 0:
            continue
        end = min(act.t + 60.0 * act.minutes, stop)
        for other in tl.feedback:
            if other.kind == AVAILABLE_KIND and other.door == act.door and act.t < other.t < end:
                end = other.t
        for door in [act.door] if act.door else tl.doors:
            if end > act.t:
                out.setdefault(door, []).append(Span(act.t, end))
    return out


def response_counts(tl: Timeline, interval: float) -> ResponseCounts:
    """Successes, opportunities and latencies of one trial (module docstring)."""
    eps = episodes(tl)
    windows = declared_windows(tl)
    dues: list[tuple[float, int]] = []
    for i, ep in enumerate(eps):
        k = 0
        while ep.start + k * interval < ep.end - TOL:
            dues.append((ep.start + k * interval, i))
            k += 1
    counts = ResponseCounts()
    credited: set[tuple[float, int]] = set()
    skipped: set[tuple[float, int]] = set()
    answered: set[int] = set()
    for g, door in tl.goes:
        waiting = [i for i, ep in enumerate(eps) if ep.door == door and ep.start - TOL <= g <= ep.end + TOL]
        candidates = [(d, i) for d, i in dues if i in waiting and d <= g + TOL]
        if not candidates:
            counts.unprompted += 1
            continue
        latest = max(d for d, _ in candidates)
        # Robots whose decision fell at the same moment: the model takes them in id order and stops at
        # the one that sends her; which one that was the log cannot tell, so the first is credited and
        # the others, decided no more once she left, are not opportunities.
        tied = sorted((i for d, i in candidates if d >= latest - TOL), key=lambda i: eps[i].robot)
        credited.add(next((d, i) for d, i in candidates if i == tied[0] and d >= latest - TOL))
        skipped.update((d, i) for d, i in candidates if d >= latest - TOL and i != tied[0])
        counts.ties += len(tied) > 1
        counts.successes += 1
        for i in waiting:
            if i not in answered:
                answered.add(i)
                counts.latencies.append(g - eps[i].start)

    def at_desk(t: float) -> bool:
        return not any(trip.start - TOL <= t < trip.end for trip in tl.trips)

    def declared(door: str, t: float) -> bool:
        return any(s.start <= t < s.end for s in windows.get(door, []))

    for d, i in dues:
        if (d, i) in credited or (d, i) in skipped:
            continue
        door = eps[i].door
        if at_desk(d) and not tl.is_open(door, d) and not declared(door, d):
            counts.opportunities += 1
    counts.opportunities += counts.successes
    counts.answered = len(answered)
    counts.censored = len(eps) - len(answered)
    return counts


def fit_door_probability(trials: Sequence[tuple[str, Timeline]], interval: float, base: float) -> Fit:
    """``trials``: (condition, timeline) of every complete trial."""
    total = ResponseCounts()
    per_condition: dict[str, dict[str, int]] = {}
    for condition, tl in trials:
        c = response_counts(tl, interval)
        total.add(c)
        row = per_condition.setdefault(condition, {"successes": 0, "opportunities": 0, "trials": 0})
        row["successes"] += c.successes
        row["opportunities"] += c.opportunities
        row["trials"] += 1
    est = clopper_pearson(total.successes, total.opportunities)
    identified = total.opportunities >= MIN_OPPORTUNITIES and total.successes >= MIN_SUCCESSES
    q1, median, q3 = quartiles(total.latencies)
    note = (
        f"decision_interval kept at its configured {interval:g} s: opportunities are counted on that grid. "
        f"Pooled over {len(trials)} trials of every condition (each shows her the robots waiting)."
    )
    if total.ties:
        note += (
            f" {total.ties} trips followed decisions about two or more robots at the same moment: the first robot "
            "is credited and the others are not counted (the model stops deciding once she leaves)."
        )
    if total.unprompted:
        note += f" {total.unprompted} trips to the door had no robot waiting there and are not counted."
    return Fit(
        param="door_probability",
        estimate=est.value if total.opportunities else base,
        low=_finite(est.low),
        high=_finite(est.high),
        n=total.opportunities,
        method="successes / decision opportunities counted by the model's rule; Clopper-Pearson 95 % interval",
        identified=identified,
        minimum=f">= {MIN_OPPORTUNITIES} opportunities and >= {MIN_SUCCESSES} trips",
        note=note,
        extra={
            "successes": total.successes,
            "unprompted_trips": total.unprompted,
            "per_condition": per_condition,
            "latency_median_s": _finite(median),
            "latency_q1_s": _finite(q1),
            "latency_q3_s": _finite(q3),
            "latency_answered_episodes": total.answered,
            "latency_censored_episodes": total.censored,
        },
    )


# ---------------------------------------------------------------------------- declarations


def fit_declare_time(timelines: Sequence[Timeline], resolution: float, base: float) -> Fit:
    times = [x for tl in timelines for x in tl.declaration_times()]
    est = mean_ci(times)
    low, high = _floor(est, resolution) if times else (None, None)
    return Fit(
        param="declare_time",
        estimate=est.value if times else base,
        low=low,
        high=high,
        n=len(times),
        method="mean length of the views away holding a declaration and no door trip; t 95 % interval",
        identified=len(times) >= MIN_DECLARATION_TIMES,
        minimum=f">= {MIN_DECLARATION_TIMES} declarations",
        note=f"interval at least ±{resolution:g} s (timestamp resolution)",
    )


def kept_focus(count: int, task: tuple[float, float, float], minutes: tuple[int, int], draws: int = 20_000) -> float:
    """The model's mean number of focus intervals kept in a trial when it draws ``count``: their lengths
    are whole minutes drawn uniformly from ``minutes``, and the last are dropped while they sum to more
    than 90 % of her task time (``task``: mean, sd, floor of the Gaussian). Monte Carlo with a fixed seed."""
    if count == 0:
        return 0.0
    rng = np.random.default_rng(FOCUS_SEED)
    mean, sd, floor = task
    duration = np.maximum(floor, mean + sd * rng.standard_normal(draws))
    lengths = 60.0 * rng.integers(minutes[0], minutes[1] + 1, size=(draws, count))
    return float((np.cumsum(lengths, axis=1) <= 0.9 * duration[:, None]).sum(axis=1).mean())


def _invert(curve: list[float], target: float) -> float:
    """The (interpolated) count at which the increasing ``curve`` (index = count) reaches ``target``."""
    if target <= curve[0]:
        return 0.0
    for c in range(1, len(curve)):
        if curve[c] >= target:
            step = curve[c] - curve[c - 1]
            return c - 1 + ((target - curve[c - 1]) / step if step > 0 else 1.0)
    return math.inf  # more than the model can keep: not bounded above


def fit_focus_count(
    arroch: Sequence[Timeline],
    declare_probability: float,
    task: tuple[float, float, float],
    minutes: tuple[int, int],
    base: int,
) -> Fit:
    """focus_count from the declarations per ARROCH trial (module docstring), through the model's
    rule for the intervals it keeps (``task`` and ``minutes``: the values written for those)."""
    finished = [tl for tl in arroch if tl.task_done is not None]
    count = sum(len(tl.declarations()) for tl in finished)
    minimum = f">= {MIN_ARROCH_TRIALS} ARROCH trials with her task done"
    method = (
        "declarations per ARROCH trial (Poisson, Garwood 95 % interval) / declare_probability = focus intervals "
        "kept per trial, matched to the model's mean kept of focus_count drawn"
    )
    if not finished or declare_probability <= 0:
        return Fit("focus_count", base, None, None, len(finished), method, False, minimum, "no ARROCH trial finished")
    rate = poisson_ci(count, len(finished))
    curve = [kept_focus(c, task, minutes) for c in range(MAX_FOCUS_COUNT + 1)]
    kept = rate.value / declare_probability
    estimate = min(range(len(curve)), key=lambda c: abs(curve[c] - kept))
    low = _invert(curve, rate.low / declare_probability)
    high = _invert(curve, rate.high / declare_probability)
    shown = ", ".join(f"{c}: {curve[c]:.2f}" for c in range(max(0, estimate - 1), min(len(curve), estimate + 3)))
    note = (
        f"{count} declarations in {len(finished)} ARROCH trials = {rate.value:.3f} per trial; / declare_probability "
        f"{declare_probability:g} = {kept:.3f} focus intervals per trial. The model drops the last intervals while "
        f"they exceed 90 % of her task time; for task {task[0]:.4g} ± {task[1]:.4g} s and {minutes[0]}-{minutes[1]} "
        f"minute intervals it keeps on average (drawn: kept) {shown}; the nearest is {estimate}. "
        "Undeclared intervals leave no trace."
    )
    if math.isinf(high):
        note += " The upper bound is open: more intervals than that would not fit in her task."
    return Fit(
        param="focus_count",
        estimate=estimate,
        low=low,
        high=high,  # inf when open
        n=len(finished),
        method=method,
        identified=len(finished) >= MIN_ARROCH_TRIALS,
        minimum=minimum,
        note=note,
        extra={"declarations": count, "declarations_per_trial": _finite(rate.value), "kept_per_trial": kept},
    )


def _widen(n: int, k: int) -> int:
    """How many whole minutes a bound may still move: the largest j with (k / (k + j))^n >= UNSEEN_LEVEL."""
    j = 0
    while (k / (k + j + 1)) ** n >= UNSEEN_LEVEL:
        j += 1
    return j


def fit_focus_minutes(arroch: Sequence[Timeline], base: tuple[int, int]) -> tuple[Fit, Fit]:
    minutes = [g[0].minutes for tl in arroch for g in tl.declarations() if g[0].minutes > 0]
    n = len(minutes)
    identified = n >= MIN_DECLARATIONS
    minimum = f">= {MIN_DECLARATIONS} declarations"
    method = "observed smallest / largest minutes declared; bound widened while unseen values stay >= 2.5 % likely"
    if not minutes:
        return tuple(  # type: ignore[return-value]
            Fit(p, b, None, None, 0, method, False, minimum, "no declaration")
            for p, b in zip(("focus_min_minutes", "focus_max_minutes"), base, strict=True)
        )
    lo, hi = min(minutes), max(minutes)
    j = _widen(n, hi - lo + 1)
    note = "declarations of each length: " + ", ".join(f"{m} min: {minutes.count(m)}" for m in sorted(set(minutes)))
    return (
        Fit("focus_min_minutes", lo, max(1, lo - j), lo, n, method, identified, minimum, note),
        Fit("focus_max_minutes", hi, hi, hi + j, n, method, identified, minimum, note),
    )


# ---------------------------------------------------------------------------- puzzle and interruptions


@dataclass
class MoveIntervals:
    """One trial's working times between consecutive puzzle moves, by what came between them."""

    plain: list[float] = field(default_factory=list)  # nothing took her away
    door: list[float] = field(default_factory=list)  # exactly one door trip
    view: list[float] = field(default_factory=list)  # a view away, no trip
    several: int = 0  # two or more trips: left out

    @property
    def usual(self) -> float:
        """Length-biased mean of the uninterrupted intervals (module docstring)."""
        total = sum(self.plain)
        return sum(x * x for x in self.plain) / total if total > 0 else NAN


def move_intervals(tl: Timeline) -> MoveIntervals:
    away = union([Span(t.start, t.end) for t in tl.trips] + list(tl.views_away))
    out = MoveIntervals()
    moves = [m.t for m in tl.moves if tl.start <= m.t <= tl.work_end + TOL]
    for a, b in zip(moves, moves[1:], strict=False):
        gone = overlap(away, a, b)
        working = (b - a) - gone
        trips = sum(1 for t in tl.trips if a <= t.start < b)
        if trips == 0 and gone <= TOL:
            out.plain.append(working)
        elif trips == 1:
            out.door.append(working)
        elif trips == 0:
            out.view.append(working)
        else:
            out.several += 1
    return out


def fit_interruption(timelines: Sequence[Timeline], resolution: float, base: float) -> Fit:
    """The interruption cost of a door trip, and (reported only) the extra after a view away."""
    door_extra: list[float] = []
    view_extra: list[float] = []
    several = 0
    for tl in timelines:
        iv = move_intervals(tl)
        several += iv.several
        if math.isnan(iv.usual):
            continue
        door_extra += [x - iv.usual for x in iv.door]
        view_extra += [x - iv.usual for x in iv.view]
    est = mean_ci(door_extra)
    n = len(door_extra)
    low, high = _floor(est, resolution) if n else (None, None)
    value = est.value if n else base
    note = (
        "measured on every door trip; the model charges interruption_cost only to trips during a focus interval. "
        f"Interval at least ±{resolution:g} s (timestamp resolution)."
    )
    if n and value < 0:
        note += f" The estimate {value:.3f} s is below 0: written as 0 (the model's floor)."
    if several:
        note += f" {several} intervals with two or more trips left out."
    view = mean_ci(view_extra)
    return Fit(
        param="interruption_cost",
        estimate=max(0.0, value),
        low=low,
        high=high,
        n=n,
        method=(
            "working time between the moves around a door trip minus her length-biased usual time between "
            "moves in that trial; mean and t 95 % interval"
        ),
        identified=n >= MIN_INTERRUPTIONS,
        minimum=f">= {MIN_INTERRUPTIONS} move intervals holding one door trip",
        note=note,
        extra={  # reported only: the model has no cost for looking away from the puzzle
            "view_away_extra_s": _finite(view.value),
            "view_away_extra_low_s": _finite(view.low),
            "view_away_extra_high_s": _finite(view.high),
            "view_away_intervals": len(view_extra),
        },
    )


def fit_task(timelines: Sequence[Timeline], interruption_cost: float, base: tuple[float, float]) -> tuple[Fit, Fit]:
    """task_mean and task_std from each finished trial's active time less ``interruption_cost`` per trip."""
    finished = [tl for tl in timelines if tl.task_done is not None]
    times, rates = [], []
    for tl in finished:
        trips = sum(1 for t in tl.trips if tl.start <= t.start < tl.work_end)
        active = tl.active_time()
        times.append(active - trips * interruption_cost)
        placed = max((m.placed for m in tl.moves), default=0)
        if active > 0 and placed:
            rates.append(placed / (active / 60.0))
    mean = mean_ci(times)
    sd = sd_ci(times)
    rate = mean_ci(rates)
    n = len(times)
    ok = n >= MIN_TASK_TRIALS
    note = (
        f"active time (at her desk in the puzzle view) less {interruption_cost:g} s per door trip before she "
        "finished. Each trial counts as one draw; a participant's trials may be alike, which these intervals "
        "do not allow for."
    )
    extra = {
        "pieces_per_active_minute": _finite(rate.value),
        "pieces_per_active_minute_low": _finite(rate.low),
        "pieces_per_active_minute_high": _finite(rate.high),
    }
    minimum = f">= {MIN_TASK_TRIALS} trials with her task done"
    return (
        Fit(
            "task_mean",
            mean.value if n else base[0],
            _finite(mean.low),
            _finite(mean.high),
            n,
            "mean active puzzle time to completion; t 95 % interval",
            ok,
            minimum,
            note,
            extra,
        ),
        Fit(
            "task_std",
            sd.value if n > 1 else base[1],
            _finite(sd.low),
            _finite(sd.high),
            n,
            "standard deviation of the active puzzle time (n - 1); chi-square 95 % interval",
            ok,
            minimum,
            note,
        ),
    )


def time_resolution(metrics: Sequence[dict[str, Any] | None], default: float) -> float:
    """The simulator's tick recorded in the trials' metrics (params.engine.tick), else ``default``."""
    ticks = []
    for m in metrics:
        tick = ((m or {}).get("params") or {}).get("engine", {}).get("tick")
        if isinstance(tick, int | float) and not isinstance(tick, bool) and tick > 0:
            ticks.append(float(tick))
    return float(np.max(ticks)) if ticks else default
