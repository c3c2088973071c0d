"""Run a participant's next trial: the world, her tablet page in the trial's condition, the
experimenter's console, and what the trial leaves in the study folder.

  arroch study run STUDY --participant P03 [--retry] [--dry-run] [--console-port N]

The trial is the participant's first one not complete (a trial found ``running`` — its runner died —
is first marked incomplete; an incomplete one runs again only with ``--retry``, its earlier log and
answers kept in ``attempt-<k>/``). The runner writes the trial's ``page.json``, marks it running and
starts the world (``arroch up --human participant --study-trial page.json ...``, recorded to
``run/<timestamp>/``), then prints the tablet page's URL (open it on her tablet) and the console's
(open it in the experimenter's browser). While the trial runs it writes ``log.jsonl`` line by line and
``questionnaire.json`` when her answers come.

Consent: before her first trial the page shows the consent form (STUDY/consent.txt) and the world
is held paused until she answers; refusing ends the trial and marks hers incomplete.

The trial is complete when the mission is done and her questionnaire has come; it is incomplete
(with the reason, in trial.json) when the world stops early, the experimenter aborts it or ends it
without the questionnaire, or the runner is stopped (Ctrl-C, SIGTERM). Either way the world is
stopped (SIGTERM, then SIGKILL after --stop-timeout) and everything written so far is kept.

Exit codes: 0 the trial is complete, or all of hers are; 1 it is incomplete, or an incomplete trial
waits for --retry, or another runner holds her trials; 2 a bad study folder or option; 128+N
stopped by signal N.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import logging
import os
import shlex
import sys
import time
from pathlib import Path
from typing import Any

from protocol.keys import Keys
from runtime.clock import make_clock
from runtime.runner import LOG_FORMAT
from runtime.transport import ZenohOptions, options_from

from .console import Console
from .layout import CONDITION_METHOD, PlannedParticipant, StudyError, StudyFolder, StudyPlan
from .page import consent_form, consent_needed, page_content, write_page
from .progress import TrialProgress
from .selection import (
    ParticipantLock,
    Selection,
    begin_attempt,
    finish,
    mark_participant_incomplete,
    next_trial,
    recover_interrupted,
)
from .trial import CommandRefused, TrialRun
from .trial_log import Questionnaires, TrialLog
from .trial_service import TrialService
from .world import UP, World, WorldSpec, option_value, up_options, world_spec

log = logging.getLogger("arroch.study.run")

EXIT_OK, EXIT_INCOMPLETE, EXIT_USAGE = 0, 1, 2
UP_ENV = "ARROCH_STUDY_UP"  # the command that starts a world, for rehearsals and tests (as --up-command)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("study", metavar="STUDY", help="the study folder (written by arroch study plan)")
    parser.add_argument("--participant", required=True, metavar="PID", help="her pseudonymous id, e.g. P03")
    parser.add_argument(
        "--retry",
        action="store_true",
        help="run her incomplete trial again as a new attempt (the earlier one's files go to attempt-<k>/)",
    )
    parser.add_argument(
        "--dry-run", action="store_true", help="print what would be started and written, start and write nothing"
    )
    parser.add_argument(
        "--console-host",
        default="127.0.0.1",
        metavar="ADDR",
        help="where the experimenter's console listens (default 127.0.0.1: this machine only; it is plain HTTP)",
    )
    parser.add_argument(
        "--console-port", type=int, default=0, metavar="N", help="the console's port (default 0: any free port)"
    )
    parser.add_argument(
        "--up-command",
        metavar="CMD",
        default=os.environ.get(UP_ENV),
        help=f"the command that starts the world, options appended (default: this Python's 'arroch up'; env {UP_ENV})",
    )
    parser.add_argument(
        "--start-timeout",
        type=float,
        default=60.0,
        metavar="S",
        help="seconds to wait for the world's Zenoh network (default 60)",
    )
    parser.add_argument(
        "--stop-timeout",
        type=float,
        default=20.0,
        metavar="S",
        help="seconds the world gets to stop after SIGTERM before SIGKILL (default 20)",
    )


def say(text: str) -> None:
    """A line for the experimenter (stdout), apart from the log (stderr)."""
    print(text, flush=True)


# ---------------------------------------------------------------------------- main


def main(args: argparse.Namespace) -> int:
    try:
        folder = StudyFolder(args.study)
        plan = folder.plan()
        participant = plan.participant(args.participant)
        folder.participant_dir(participant.id)  # refuses an id that is not pseudonymous
        if not 0 <= args.console_port <= 65535:
            raise StudyError(f"--console-port {args.console_port} is not a port")
        if args.dry_run:
            return dry_run(args, folder, plan, participant)
        lock = ParticipantLock(folder, participant.id)
    except StudyError as exc:
        log.error("%s", exc)
        return EXIT_USAGE
    try:
        lock.acquire()
    except StudyError as exc:
        log.error("%s", exc)
        return EXIT_INCOMPLETE
    try:
        for note in recover_interrupted(folder, participant):
            say(note)
        selection = next_trial(folder, participant, retry=args.retry)
        say(selection.message)
        if selection.action == "done":
            return EXIT_OK
        if selection.action == "blocked":
            return EXIT_INCOMPLETE
        return run_trial(args, folder, plan, participant, selection)
    except StudyError as exc:
        log.error("%s", exc)
        return EXIT_USAGE
    finally:
        lock.release()


def _runner_zenoh(args: argparse.Namespace) -> ZenohOptions | None:
    """The runner's Zenoh options when given on its command line (not from the environment)."""
    given = any(getattr(args, name, None) for name in ("connect", "zenoh_config", "listen", "mode"))
    return options_from(args) if given else None


def _prepare(
    args: argparse.Namespace, folder: StudyFolder, plan: StudyPlan, participant: PlannedParticipant, sel: Selection
) -> tuple[dict[str, Any], str, WorldSpec]:
    """page.json's content, the consent form's SHA-256 and the world: everything checked before anything
    is written (StudyError otherwise)."""
    assert sel.trial is not None
    trial = sel.trial
    pid = participant.id
    if consent_needed(folder, pid):
        text, sha = consent_form(folder)
    else:  # given before: the form she consented to is the one a withdrawal refers to
        earlier = folder.consent(pid)
        text, sha = None, earlier.form_sha256 if earlier else ""
    content = page_content(plan, pid, trial, consent_text=text)
    namespace = (
        args.namespace
        or option_value(list(plan.world.up_args), "--namespace")
        or f"study-{pid}-t{trial.index}-a{sel.attempt}"
    )
    try:
        Keys(namespace)
        up_command = shlex.split(args.up_command) if args.up_command else None
        spec = world_spec(
            plan,
            page_file=(folder.trial_dir(pid, trial.id) / "page.json").resolve(),
            run_dir=folder.run_dir(pid, trial.id).resolve(),
            namespace=namespace,
            method=CONDITION_METHOD[trial.condition],
            seed=trial.world_seed,
            up_command=up_command,
            site=getattr(args, "site", None),
            log_level=getattr(args, "log_level", None),
            runner_zenoh=_runner_zenoh(args),
            takes=up_options(up_command or list(UP)),
        )
    except ValueError as exc:
        raise StudyError(str(exc)) from None
    return content, sha, spec


def dry_run(args: argparse.Namespace, folder: StudyFolder, plan: StudyPlan, participant: PlannedParticipant) -> int:
    for trial in participant.trials:
        if folder.trial_state(participant.id, trial).status == "running":
            say(f"{trial.id} is marked running: a real run first checks no runner holds it, then marks it incomplete")
    selection = next_trial(folder, participant, retry=args.retry)
    say(selection.message)
    if selection.action != "run" or selection.trial is None:
        return EXIT_OK if selection.action == "done" else EXIT_INCOMPLETE
    content, _sha, spec = _prepare(args, folder, plan, participant, selection)
    trial_dir = folder.trial_dir(participant.id, selection.trial.id)
    say(f"dry run: nothing is started or written. Attempt {selection.attempt} of {selection.trial.id} would:")
    if selection.attempt > 1:
        earlier = trial_dir / f"attempt-{selection.attempt - 1}"
        say(f"  move the earlier attempt's log.jsonl, questionnaire.json, page.json to {earlier}/")
    say(f"  write {trial_dir / 'page.json'}:")
    for line in json.dumps(content, indent=2).splitlines():
        say(f"    {line}")
    say(f"  mark {trial_dir / 'trial.json'} running (attempt {selection.attempt})")
    if content["consent"]["required"]:
        where = folder.consent_file(participant.id)
        say(f"  take her consent on the tablet page first (the world held paused), into {where}")
    say(f"  start the world (namespace {spec.namespace}):")
    say(f"    {shlex.join(spec.argv)}")
    say(f"  write {trial_dir / 'log.jsonl'} and {trial_dir / 'questionnaire.json'} as the trial goes")
    say(f"  serve the experimenter's console on http://{args.console_host}:{args.console_port or '<free port>'}/")
    return EXIT_OK


# ---------------------------------------------------------------------------- one trial


def run_trial(
    args: argparse.Namespace, folder: StudyFolder, plan: StudyPlan, participant: PlannedParticipant, sel: Selection
) -> int:
    assert sel.trial is not None and sel.state is not None
    trial, pid = sel.trial, participant.id
    content, sha, spec = _prepare(args, folder, plan, participant, sel)
    service = TrialService(
        spec.namespace, spec.zenoh, participant=pid, trial=trial.id, clock=make_clock(getattr(args, "clock", "sim"))
    )
    clock = service.clock
    progress = TrialProgress(
        participant=pid,
        trial=trial.id,
        condition=trial.condition,
        attempt=sel.attempt,
        world=plan.world.kind,
        questionnaires=list(plan.questionnaires),
        site_time=lambda: clock.now() if clock.synced else None,
    )
    runs: list[TrialRun] = []  # the console's commands go to the trial once it exists
    console = Console(
        progress.snapshot, lambda kind, **a: _submit(runs, kind, **a), host=args.console_host, port=args.console_port
    )
    if args.console_host not in ("127.0.0.1", "localhost", "::1"):
        log.warning(
            "the console listens on %s in plain HTTP: its token crosses that network in clear", args.console_host
        )
    try:
        url = console.start()  # before anything is written: a taken port leaves the trial as it was
    except OSError as exc:
        log.error("%s; nothing was started or written", exc)
        return EXIT_USAGE
    try:
        return _attempt(args, folder, plan, participant, sel, content, sha, spec, service, progress, runs, url)
    finally:
        console.stop()


def _submit(runs: list[TrialRun], kind: str, **args: Any) -> concurrent.futures.Future:
    if runs:
        return runs[0].submit(kind, **args)
    future: concurrent.futures.Future = concurrent.futures.Future()
    future.set_exception(CommandRefused("the trial is starting"))
    return future


def _attempt(
    args: argparse.Namespace,
    folder: StudyFolder,
    plan: StudyPlan,
    participant: PlannedParticipant,
    sel: Selection,
    content: dict[str, Any],
    sha: str,
    spec: WorldSpec,
    service: TrialService,
    progress: TrialProgress,
    runs: list[TrialRun],
    console_url: str,
) -> int:
    """One attempt, from marking it running to its outcome in trial.json (whatever happens)."""
    assert sel.trial is not None and sel.state is not None
    trial, pid = sel.trial, participant.id
    state = begin_attempt(folder, sel.state)
    page_file = write_page(folder, pid, trial.id, content)
    trial_dir = page_file.parent
    file_log = _log_to(trial_dir / "runner.log")
    started = time.monotonic()
    world = World(spec.argv)
    trial_log = TrialLog(folder.log_file(pid, trial.id))
    run = TrialRun(
        folder=folder,
        participant=pid,
        trial=trial.id,
        world_kind=plan.world.kind,
        world=world,
        progress=progress,
        trial_log=trial_log,
        questionnaires=Questionnaires(folder.questionnaire_file(pid, trial.id), list(plan.questionnaires)),
        consent_required=content["consent"]["required"],
        consent_sha256=sha,
        on_urls=_show_tablet_urls,
    )
    runs.append(run)
    service.install_signal_handlers()  # from here on, Ctrl-C/SIGTERM end the trial in order
    log.info("%s attempt %d: page %s, namespace %s", trial.id, state.attempt, page_file, spec.namespace)
    try:
        say(f"console: {console_url}")
        if content["consent"]["required"]:
            say("consent: her consent is taken on the tablet page first; the world waits for it")
        run.attach(service)
        world.start()
        problem = _join(service, world, args.start_timeout)
        if problem:
            run.end("incomplete", problem)
            for line in world.last_lines():
                log.error("world: %s", line)
        else:
            service.run()  # until the trial ends (TrialRun.end) or a signal; closes the session
    except OSError as exc:  # the world's command could not be started
        log.error("%s", exc)
        run.end("incomplete", f"could not start the world: {exc}")
    except BaseException as exc:  # a bug: the trial must still be left in a known state
        run.end("incomplete", f"the runner failed: {type(exc).__name__}: {exc}")
        raise
    finally:
        status, reason = run.outcome or ("incomplete", "the runner stopped without an outcome")
        run.refuse_pending()
        world.stop(args.stop_timeout, hurry=lambda: service.signals.count >= 2)
        service.close()
        trial_log.close()
        finish(folder, state, status, reason)
        if run.consent_ended:
            marked = mark_participant_incomplete(folder, participant, run.consent_ended, except_trial=trial.id)
            if marked:
                say(f"{pid}: {', '.join(marked)} marked incomplete ({run.consent_ended})")
        logging.getLogger().removeHandler(file_log)
        file_log.close()
    say(summary(trial.id, state.attempt, status, reason, run.mission, run.questionnaires.answers, started, trial_dir))
    if service.signals.received:
        return 128 + int(service.signals.first or 0)
    return EXIT_OK if status == "complete" else EXIT_INCOMPLETE


def _join(service: TrialService, world: World, timeout: float) -> str:
    """Open the runner's session on the world's network, which comes up with the world: retried
    until it works, the world stops, a signal comes or ``timeout`` passes. Returns what went wrong."""
    deadline = time.monotonic() + timeout
    last: Exception | None = None
    while True:
        if service.signals.received:
            return f"interrupted: the runner received {service.signals.name} before the world was up"
        if not world.running():
            return f"the world stopped before the mission ended: arroch up {world.describe_exit()}"
        try:
            service.open()
            return ""
        except Exception as exc:  # zenoh refuses while the router is not listening yet
            last = exc
            service.close()
        if time.monotonic() > deadline:
            return f"could not join the world's Zenoh network within {timeout:.0f} s: {last}"
        time.sleep(0.1)


def _show_tablet_urls(urls: list[str]) -> None:
    say("tablet page (open it on her tablet):")
    for url in urls:
        say(f"  {url}")


def _log_to(path: Path) -> logging.Handler:
    """The runner's log also goes to the trial's folder (runner.log), what happened kept with the data."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(path, encoding="utf-8")
    handler.setFormatter(logging.Formatter(LOG_FORMAT))
    handler.setLevel(logging.INFO)
    logging.getLogger().addHandler(handler)
    return handler


def summary(
    tid: str,
    attempt: int,
    status: str,
    reason: str,
    mission: dict[str, Any],
    answers: dict[str, Any],
    started: float,
    trial_dir: Path,
) -> str:
    """The trial in one line."""
    parts = [f"{tid} {status} (attempt {attempt}{': ' + reason if reason else ''})"]
    if mission:
        done = "completed" if mission.get("completed") else "ended unfinished"
        parts.append(f"mission {done} at t={_num(mission.get('time'))} s")
        team = mission.get("team_completion_time")
        if team is not None:
            parts.append(f"team {_num(team)} s")
        agents = mission.get("agent_completion_times") or {}
        if isinstance(agents, dict) and agents.get("human") is not None:
            parts.append(f"her task {_num(agents['human'])} s")
        if mission.get("human_door_openings") is not None:
            parts.append(f"{mission['human_door_openings']} door opening(s) by her")
    parts.append(f"questionnaire {', '.join(sorted(answers)) or 'none'}")
    parts.append(f"{(time.monotonic() - started) / 60:.1f} min")
    parts.append(str(trial_dir))
    return "; ".join(parts)


def _num(value: Any) -> str:
    return f"{value:.1f}" if isinstance(value, (int, float)) else "?"


if __name__ == "__main__":  # ``python -m services.study.run`` is ``arroch study run``
    from runtime.runner import add_common_arguments, setup_logging

    parser = argparse.ArgumentParser(
        prog="arroch study run", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_common_arguments(parser)
    add_arguments(parser)
    parsed = parser.parse_args()
    setup_logging(parsed.log_level)
    sys.exit(main(parsed))
