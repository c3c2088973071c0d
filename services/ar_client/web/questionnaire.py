"""The questionnaires a participant answers after a trial, and the check of her answers.

- ``arroch-q``: the paper's items Q1-Q5 (its "Real-world Experiments" section, wording as printed)
  on its 1-5 scale with its labels;
- ``nasa-tlx``: raw NASA-TLX (Hart & Staveland 1988), the six subscales on the paper form's 21
  marks, 0-100 in steps of 5, with the form's questions and end anchors (Performance runs from
  "Perfect" to "Failure"). Raw: no pairwise weighting.

The page builds its form from :func:`instruments_json`, so wording and scale live here only; the
server checks every submitted answer with :func:`check_answers`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


class AnswersRefused(ValueError):
    """Answers that do not fit their instrument; the message says which item and why."""


@dataclass(frozen=True)
class Item:
    id: str
    text: str
    title: str = ""  # a subscale's name (TLX)
    low: str = ""  # the anchor at the scale's low end (TLX)
    high: str = ""


@dataclass(frozen=True)
class Instrument:
    id: str
    title: str
    intro: str
    items: tuple[Item, ...]
    lo: int
    hi: int
    step: int
    labels: tuple[tuple[int, str], ...] = ()  # a label per point (Likert)

    def values(self) -> list[int]:
        return list(range(self.lo, self.hi + 1, self.step))


ARROCH_Q = Instrument(
    id="arroch-q",
    title="Your opinion of this trial",
    intro="How much do you agree with each statement about the trial you just did?",
    items=(
        Item("Q1", "The tasks were easy to understand"),
        Item("Q2", "It was easy to keep track of robot status"),
        Item("Q3", "I could focus on my task with minimal distraction from robot"),
        Item("Q4", "The task was not mentally demanding (e.g., remembering, deciding, and thinking)"),
        Item("Q5", "I enjoyed working with the robot and would like to use such a system in the future"),
    ),
    lo=1,
    hi=5,
    step=1,
    labels=(
        (1, "Strongly disagree"),
        (2, "Somewhat disagree"),
        (3, "Neutral"),
        (4, "Somewhat agree"),
        (5, "Strongly agree"),
    ),
)

NASA_TLX = Instrument(
    id="nasa-tlx",
    title="Workload (NASA-TLX)",
    intro="Mark each scale at the point that matches your experience of the trial.",
    items=(
        Item("mental", "How mentally demanding was the task?", "Mental Demand", "Very Low", "Very High"),
        Item("physical", "How physically demanding was the task?", "Physical Demand", "Very Low", "Very High"),
        Item("temporal", "How hurried or rushed was the pace of the task?", "Temporal Demand", "Very Low", "Very High"),
        Item(
            "performance",
            "How successful were you in accomplishing what you were asked to do?",
            "Performance",
            "Perfect",
            "Failure",
        ),
        Item(
            "effort",
            "How hard did you have to work to accomplish your level of performance?",
            "Effort",
            "Very Low",
            "Very High",
        ),
        Item(
            "frustration",
            "How insecure, discouraged, irritated, stressed, and annoyed were you?",
            "Frustration",
            "Very Low",
            "Very High",
        ),
    ),
    lo=0,
    hi=100,
    step=5,
)

INSTRUMENTS: dict[str, Instrument] = {i.id: i for i in (ARROCH_Q, NASA_TLX)}


def check_answers(instrument_id: str, answers: Any) -> dict[str, int]:
    """``answers`` (item id → value) for the instrument, every item answered on its scale; else
    :class:`AnswersRefused` naming the item."""
    instrument = INSTRUMENTS.get(instrument_id)
    if instrument is None:
        raise AnswersRefused(f"no questionnaire {instrument_id!r}")
    if not isinstance(answers, dict):
        raise AnswersRefused(f"{instrument_id}: answers are a map of item to value")
    ids = [item.id for item in instrument.items]
    unknown = sorted(set(answers) - set(ids))
    if unknown:
        raise AnswersRefused(f"{instrument_id}: no item {unknown[0]!r} (items: {', '.join(ids)})")
    missing = [i for i in ids if i not in answers]
    if missing:
        raise AnswersRefused(f"{instrument_id}: item {missing[0]} is not answered; every item must be")
    checked: dict[str, int] = {}
    for item_id in ids:
        value = answers[item_id]
        if isinstance(value, bool) or not isinstance(value, int):
            raise AnswersRefused(f"{instrument_id}: {item_id}: {value!r} is not a whole number")
        if not instrument.lo <= value <= instrument.hi or (value - instrument.lo) % instrument.step:
            raise AnswersRefused(
                f"{instrument_id}: {item_id}: {value} is not on the scale {instrument.lo} to {instrument.hi}"
                + (f" in steps of {instrument.step}" if instrument.step != 1 else "")
            )
        checked[item_id] = value
    return checked


def instruments_json(ids: list[str]) -> list[dict[str, Any]]:
    """The instruments as the page draws them, in the trial's order."""
    out = []
    for instrument_id in ids:
        i = INSTRUMENTS[instrument_id]
        out.append(
            {
                "id": i.id,
                "title": i.title,
                "intro": i.intro,
                "values": i.values(),
                "labels": {str(v): text for v, text in i.labels},
                "items": [
                    {"id": it.id, "text": it.text, "title": it.title, "low": it.low, "high": it.high} for it in i.items
                ],
            }
        )
    return out
