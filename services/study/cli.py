"""``arroch study plan|run|console|report|calibrate``: a user study with real participants.

A study is one folder (:mod:`.layout`): ``plan`` writes its plan before anyone takes part
(participants × conditions, orders counterbalanced, seeded); ``run --participant P03`` runs that
participant's next trial (the world, the tablet page in the trial's condition, her puzzle, the
experimenter's console, the questionnaire after it); ``report`` analyses the trials (paired tests,
the paper's figures, a tidy CSV); ``calibrate`` fits the simulated human's parameters to what the
participants did and writes a human config the simulator and every sweep read.

Examples:
  arroch study plan --participants 12 --conditions arroch,map --seed 7 --out studies/pilot
  arroch study run studies/pilot --participant P01
  arroch study report studies/pilot
  arroch study calibrate studies/pilot            # -> studies/pilot/human.toml
  arroch sim --human-config studies/pilot/human.toml ...

Every sub-command refuses a bad folder or file before it starts (exit 2, naming the file and the
problem); docs/study.md is the researcher's guide.
"""

from __future__ import annotations

import argparse
import importlib
from typing import Any

#: Each sub-command and the module that implements it: ``add_arguments(parser)`` and ``main(args) -> int``.
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "plan": ("services.study.plan", "write a study's plan: participants x conditions, counterbalanced and seeded"),
    "run": ("services.study.run", "run a participant's next trial (world, tablet page, console, questionnaire)"),
    "report": ("services.study.report", "analyse the trials: paired tests, the paper's figures, a tidy CSV"),
    "calibrate": ("services.study.calibrate", "fit the simulated human's parameters to the trials' logs"),
}


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "study",
        help="user studies with real participants: plan, run, report, calibrate",
        description=__doc__.split("\n\n", 1)[1].split("\n\nExamples:")[0],
        epilog="Examples:" + __doc__.split("Examples:", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from runtime.runner import add_common_arguments

    sub = parser.add_subparsers(dest="study_command", metavar="SUBCOMMAND", required=True)
    for name, (module_name, summary) in SUBCOMMANDS.items():
        module = importlib.import_module(module_name)
        child = sub.add_parser(
            name,
            help=summary,
            description=(module.__doc__ or summary).strip(),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        if name == "run":
            add_common_arguments(child)
        module.add_arguments(child)
        child.set_defaults(func=module.main)
