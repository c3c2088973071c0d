"""``arroch study plan``: write a study's plan before anyone takes part.

Every participant does one trial in each condition (within participants). The order of the
conditions is counterbalanced with a Williams design: a balanced Latin square in which every
condition comes in every position equally often and, for an even number of conditions, every
condition immediately follows every other exactly once (first-order carry-over balanced); for an odd
number the square and its mirror together give that balance, each ordered pair twice. The design's
orders are dealt to participants in blocks: each block of as many participants as there are orders
gets every order once, in a seeded random arrangement, so a study stopped after whole blocks is
still balanced. Which condition is which symbol of the square is also drawn from the seed.

Seeds (numpy ``SeedSequence`` of the study seed, so the same seed gives the same plan anywhere): one
``world_seed`` per participant, shared by all her trials (the same simulated world in every
condition: the comparison is paired); one ``puzzle_seed`` per trial, different in every trial (her
puzzle is shuffled anew each time, as in the paper, so she cannot learn it). All seeds are distinct
within a study and below 2**31.

The plan is written once (``study.json``) and never overwritten. A plain ``consent.txt`` with
placeholders is written beside it when the folder has none: the researcher must replace every
``<<...>>`` with the study's own wording and ethics approval before the first participant.
"""

from __future__ import annotations

import argparse
import secrets
import sys
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from .layout import (
    CONDITIONS,
    PARTICIPANT_ID,
    QUESTIONNAIRES,
    PlannedParticipant,
    PlannedTrial,
    PuzzleSpec,
    StudyError,
    StudyFolder,
    StudyPlan,
    WorldSpec,
    write_json,
)

SEED_LIMIT = 2**31  # every seed below this: fits any int32 seed option downstream

CONSENT_TEMPLATE = """\
CONSENT FORM - EDIT BEFORE USE
(Researcher: replace every <<...>> with your study's own wording and delete this line.
 Your ethics board's approved text takes precedence over anything written here.)

Study: <<STUDY TITLE>>
Researcher: <<NAME, INSTITUTION, EMAIL OR PHONE>>
Ethics approval: <<BOARD NAME AND APPROVAL NUMBER>>

What you will do
You will solve a jigsaw puzzle on a tablet while robots deliver objects nearby. Some robots will
need you to open a door for them. The tablet shows you the robots. You will do this {trials} times,
each time with a different way of showing the robots, and answer a short questionnaire after each
time. It takes about <<MINUTES>> minutes in all.

What we record
What you do on the tablet (puzzle moves, taps, which view you look at), when you open the door,
where the robots are, and your questionnaire answers. We do not record your name with this data:
you are known only by a code such as P03. <<SAY HERE IF YOU RECORD VIDEO OR AUDIO; OTHERWISE: We do
not record video or audio of you.>>

Risks
<<DESCRIBE ANY RISKS, e.g. moving robots in the room, and how they are kept safe.>>

Your choice
Taking part is voluntary. You may stop at any time without giving a reason, and ask for your data
to be deleted until <<DATE OR EVENT AFTER WHICH DATA CAN NO LONGER BE WITHDRAWN>>.

Questions or complaints: <<CONTACT>>

By choosing "I agree" you confirm that you have read this form and agree to take part.
"""


# ---------------------------------------------------------------------------- the design


def williams_orders(n: int) -> list[list[int]]:
    """The rows of a Williams design for ``n`` conditions (0..n-1).

    The first row is 0, 1, n-1, 2, n-2, ...; row ``i`` adds ``i`` to every entry modulo ``n``. For
    an odd ``n`` the mirrored rows are appended (a single square cannot balance carry-over then).
    """
    if n < 1:
        raise ValueError("a design needs at least one condition")
    first = [0]
    for j in range(1, n):
        first.append((j + 1) // 2 if j % 2 else n - j // 2)
    rows = [[(x + i) % n for x in first] for i in range(n)]
    if n % 2 and n > 1:
        rows += [row[::-1] for row in rows]
    return rows


def design_name(n: int) -> str:
    rows = len(williams_orders(n))
    mirror = ", square and mirror" if n % 2 and n > 1 else ""
    return f"balanced-latin-square (Williams{mirror}, {rows} orders)"


def _seed_word(ss: np.random.SeedSequence, used: set[int]) -> int:
    """A seed from ``ss`` below SEED_LIMIT that no other part of the plan has (a clash is redrawn)."""
    for word in ss.generate_state(16, dtype=np.uint32):
        value = int(word) % SEED_LIMIT
        if value not in used:
            used.add(value)
            return value
    raise RuntimeError("16 seed words all clashed: impossible unless the seed sequence is broken")


def build_plan(
    *,
    name: str,
    seed: int,
    conditions: list[str],
    participant_ids: list[str],
    questionnaires: list[str],
    puzzle: PuzzleSpec,
    world: WorldSpec,
    created: str | None = None,
) -> StudyPlan:
    """The plan: orders from the Williams design dealt in seeded blocks, seeds per participant and trial."""
    n = len(conditions)
    orders = williams_orders(n)
    order_ss, seed_ss = np.random.SeedSequence(seed).spawn(2)
    rng = np.random.default_rng(order_ss)
    symbol_to_condition = [conditions[i] for i in rng.permutation(n)]
    blocks = -(-len(participant_ids) // len(orders))
    deal = [int(r) for _ in range(blocks) for r in rng.permutation(len(orders))]
    used: set[int] = set()
    participants = []
    for k, (pid, pss) in enumerate(zip(participant_ids, seed_ss.spawn(len(participant_ids)), strict=True)):
        world_ss, *trial_ss = pss.spawn(1 + n)
        world_seed = _seed_word(world_ss, used)
        row = orders[deal[k]]
        trials = [
            PlannedTrial(
                id=f"{pid}-T{index}-{symbol_to_condition[symbol]}",
                index=index,
                condition=symbol_to_condition[symbol],  # type: ignore[arg-type]
                world_seed=world_seed,
                puzzle_seed=_seed_word(tss, used),
            )
            for index, (symbol, tss) in enumerate(zip(row, trial_ss, strict=True), 1)
        ]
        participants.append(PlannedParticipant(id=pid, trials=trials))
    return StudyPlan(
        name=name,
        seed=seed,
        created=created or datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        design=design_name(n),
        conditions=list(conditions),
        questionnaires=list(questionnaires),
        puzzle=puzzle,
        world=world,
        participants=participants,
    )


# ---------------------------------------------------------------------------- the command


def _list(text: str) -> list[str]:
    return [part.strip() for part in text.split(",") if part.strip()]


def _participant_ids(count: int | None, ids: str | None) -> list[str]:
    if ids:
        chosen = _list(ids)
        bad = [pid for pid in chosen if not PARTICIPANT_ID.match(pid)]
        if bad:
            raise StudyError(f"--ids: {', '.join(bad)} not pseudonymous (P followed by 2-4 digits, e.g. P03)")
        if len(set(chosen)) != len(chosen):
            raise StudyError("--ids: an id is given twice")
        if count is not None and count != len(chosen):
            raise StudyError(f"--participants {count} but --ids names {len(chosen)}")
        return chosen
    if count is None:
        raise StudyError("give --participants N or --ids P01,P02,...")
    if not 1 <= count <= 9999:
        raise StudyError(f"--participants {count}: between 1 and 9999")
    width = max(2, len(str(count)))
    return [f"P{i:0{width}d}" for i in range(1, count + 1)]


def _conditions(text: str) -> list[str]:
    chosen = _list(text)
    unknown = [c for c in chosen if c not in CONDITIONS]
    if unknown:
        raise StudyError(f"--conditions: {', '.join(unknown)} unknown (choose from {', '.join(CONDITIONS)})")
    if len(set(chosen)) != len(chosen):
        raise StudyError("--conditions: a condition is given twice")
    if len(chosen) < 2:
        raise StudyError("--conditions: a within-participants comparison needs at least two conditions")
    return chosen


def _questionnaires(text: str) -> list[str]:
    chosen = _list(text)
    unknown = [q for q in chosen if q not in QUESTIONNAIRES]
    if unknown or not chosen:
        raise StudyError(f"--questionnaires: choose one or more of {', '.join(QUESTIONNAIRES)}")
    return list(dict.fromkeys(chosen))


def _puzzle(text: str) -> PuzzleSpec:
    try:
        rows, cols = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise StudyError(f"--puzzle {text!r}: write ROWSxCOLS, e.g. 4x4") from None
    if not (2 <= rows <= 20 and 2 <= cols <= 20):
        raise StudyError(f"--puzzle {text}: rows and columns between 2 and 20")
    return PuzzleSpec(rows=rows, cols=cols)


def _world(args: argparse.Namespace) -> WorldSpec:
    if args.site and not Path(args.site).is_file():
        raise StudyError(f"--site {args.site} does not exist")
    if not args.rate > 0:
        raise StudyError(f"--rate {args.rate}: must be > 0")
    if not args.time_limit > 0:
        raise StudyError(f"--time-limit {args.time_limit}: must be > 0")
    site = str(Path(args.site).resolve()) if args.site else ""
    return WorldSpec(kind=args.world, site=site, mode=args.mode, rate=args.rate, time_limit=args.time_limit)


def plan_table(plan: StudyPlan) -> str:
    """The plan as a text table: one row per participant, her conditions in order."""
    n = max(len(p.trials) for p in plan.participants)
    head = ["participant", "world_seed", *(f"T{i}" for i in range(1, n + 1))]
    rows = [[p.id, str(p.trials[0].world_seed), *(t.condition for t in p.trials)] for p in plan.participants]
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in [head, *rows])


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--participants", type=int, metavar="N", help="number of participants (ids P01..PNN)")
    parser.add_argument("--ids", metavar="P01,P02,...", help="name the participants (pseudonymous ids)")
    parser.add_argument(
        "--conditions",
        default="arroch,map",
        metavar="A,B,...",
        help=f"conditions every participant does, from {', '.join(CONDITIONS)} (default arroch,map: the paper's)",
    )
    parser.add_argument("--seed", type=int, help="study seed (default: drawn now and recorded in study.json)")
    parser.add_argument(
        "--questionnaires", default="arroch-q", metavar="LIST", help="after each trial: arroch-q and/or nasa-tlx"
    )
    parser.add_argument("--puzzle", default="4x4", metavar="RxC", help="jigsaw size (default 4x4)")
    parser.add_argument("--world", choices=("virtual", "real"), default="virtual", help="simulated or real robots")
    parser.add_argument("--site", metavar="FILE", help="site file (default: the packaged office site)")
    parser.add_argument("--mode", choices=("realtime", "rate"), default="realtime", help="site clock pacing")
    parser.add_argument("--rate", type=float, default=1.0, help="site seconds per wall second in rate mode")
    parser.add_argument("--time-limit", type=float, default=1800.0, help="site seconds before a trial ends unfinished")
    parser.add_argument("--name", help="study name (default: the folder's name)")
    parser.add_argument("--out", required=True, metavar="DIR", help="the study folder to create")


def main(args: argparse.Namespace) -> int:
    try:
        folder = StudyFolder(args.out)
        if folder.plan_file.exists():
            raise StudyError(
                f"{folder.plan_file} already exists: a plan is never changed once written (choose another --out)"
            )
        participants_dir = folder.root / "participants"
        if participants_dir.is_dir() and any(participants_dir.iterdir()):
            raise StudyError(f"{participants_dir} holds participant data but {folder.plan_file} is missing")
        seed = args.seed if args.seed is not None else secrets.randbelow(SEED_LIMIT)
        if not 0 <= seed < 2**63:
            raise StudyError(f"--seed {seed}: between 0 and 2**63 - 1")
        plan = build_plan(
            name=args.name or folder.root.resolve().name,
            seed=seed,
            conditions=_conditions(args.conditions),
            participant_ids=_participant_ids(args.participants, args.ids),
            questionnaires=_questionnaires(args.questionnaires),
            puzzle=_puzzle(args.puzzle),
            world=_world(args),
        )
    except StudyError as exc:
        print(f"arroch study plan: {exc}", file=sys.stderr)
        return 2
    write_json(folder.plan_file, plan)
    print(f"study {plan.name}: {len(plan.participants)} participants x {len(plan.conditions)} conditions")
    print(f"design {plan.design}; seed {plan.seed}{'' if args.seed is not None else ' (drawn now)'}")
    print(f"plan written to {folder.plan_file}")
    if not folder.consent_form.exists():
        folder.consent_form.write_text(CONSENT_TEMPLATE.format(trials=len(plan.conditions)), encoding="utf-8")
        print(f"{folder.consent_form} written with <<placeholders>>: edit every one before the first participant")
    print()
    print(plan_table(plan))
    return 0
