"""Every planned trial of a study folder with what it left behind: its state, its metrics (the
simulator's ``mission_done`` summary), her questionnaire answers and her log, checked as read.

A trial counts as **complete** when its ``trial.json`` says so; any other status (pending, running,
incomplete) leaves it out of the analyses, and :func:`load_trials` keeps the reason so the report
can list it. A complete trial may still lack a part (no metrics: the mission never ended; the
mission ran out of time; no answers): each absence is kept as a note on the trial.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .layout import StudyError, StudyFolder, StudyPlan, read_json
from .timeline import Timeline, load_timeline

#: Each instrument's scale (the page's: arroch-q Q1-Q5 on 1-5; NASA-TLX raw, six scales 0-100).
SCALES = {"arroch-q": (1, 5), "nasa-tlx": (0, 100)}
LIKERT_ITEMS = ("Q1", "Q2", "Q3", "Q4", "Q5")


@dataclass
class TrialData:
    participant: str
    trial: str
    condition: str
    order: int  # 1-based position in her sequence
    status: str
    reason: str  # why it is not complete, or ""
    log_path: Path
    metrics_path: Path | None
    metrics: dict[str, Any] | None
    answers: dict[str, dict[str, int]]
    notes: list[str] = field(default_factory=list)  # what a complete trial lacks
    _timeline: Timeline | None = None

    @property
    def complete(self) -> bool:
        return self.status == "complete"

    @property
    def has_log(self) -> bool:
        return self.log_path.is_file()

    def timeline(self) -> Timeline:
        if self._timeline is None:
            if not self.has_log:
                raise StudyError(f"{self.log_path} does not exist")
            self._timeline = load_timeline(self.log_path)
        return self._timeline


def _number(value: Any, path: Path, name: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise StudyError(f"{path}: {name} should be a number or null, not {value!r}")
    return float(value)


def check_metrics(data: Any, path: Path) -> dict[str, Any]:
    """The fields the analysis reads, checked: a malformed metrics file is named, not guessed around."""
    if not isinstance(data, dict):
        raise StudyError(f"{path}: not a JSON object (the simulator's mission_done metrics)")
    if not isinstance(data.get("completed"), bool):
        raise StudyError(f"{path}: 'completed' should be true or false")
    _number(data.get("team_completion_time"), path, "team_completion_time")
    agents = data.get("agent_completion_times")
    if not isinstance(agents, dict) or "human" not in agents:
        raise StudyError(f"{path}: 'agent_completion_times' should map each robot and 'human' to a time")
    for agent, value in agents.items():
        _number(value, path, f"agent_completion_times.{agent}")
    return data


def check_answers(data: Any, path: Path, asked: list[str]) -> dict[str, dict[str, int]]:
    if not isinstance(data, dict):
        raise StudyError(f"{path}: not a JSON object of instrument -> answers")
    out: dict[str, dict[str, int]] = {}
    for instrument, answers in data.items():
        if instrument not in SCALES:
            raise StudyError(f"{path}: unknown instrument {instrument!r} (known: {', '.join(SCALES)})")
        if not isinstance(answers, dict):
            raise StudyError(f"{path}: {instrument} answers should be an object of item -> value")
        low, high = SCALES[instrument]
        for item, value in answers.items():
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
                raise StudyError(f"{path}: {instrument} {item} = {value!r} is off the {low}-{high} scale")
        if instrument == "arroch-q" and set(answers) - set(LIKERT_ITEMS):
            extra = ", ".join(sorted(set(answers) - set(LIKERT_ITEMS)))
            raise StudyError(f"{path}: arroch-q has items Q1-Q5, not {extra}")
        out[instrument] = dict(answers)
    return out


def load_trials(folder: StudyFolder, plan: StudyPlan | None = None) -> list[TrialData]:
    """Every planned trial, in plan order, with its files read and checked."""
    plan = plan or folder.plan()
    out = []
    for p, t, state in folder.trials():
        metrics_path = folder.metrics_file(p.id, t.id)
        metrics = check_metrics(read_json(metrics_path), metrics_path) if metrics_path else None
        qpath = folder.questionnaire_file(p.id, t.id)
        answers = check_answers(read_json(qpath), qpath, plan.questionnaires) if qpath.exists() else {}
        reason = ""
        if state.status != "complete":
            reason = state.reason or {"pending": "never run", "running": "still running (or its runner died)"}.get(
                state.status, state.status
            )
        trial = TrialData(
            participant=p.id,
            trial=t.id,
            condition=t.condition,
            order=t.index,
            status=state.status,
            reason=reason,
            log_path=folder.log_file(p.id, t.id),
            metrics_path=metrics_path,
            metrics=metrics,
            answers=answers,
        )
        if trial.complete:
            if metrics is None:
                trial.notes.append("no metrics.json: the mission never ended, its times are missing")
            elif not metrics["completed"]:
                trial.notes.append(
                    f"the mission did not finish (ended at {metrics.get('time', '?')} s): team time missing"
                )
            if not trial.has_log:
                trial.notes.append("no log.jsonl: door trips, declarations and time away are missing")
            missing = [q for q in plan.questionnaires if q not in answers]
            if missing:
                trial.notes.append(f"no answers to {', '.join(missing)}")
        out.append(trial)
    return out
