"""Command line of the restrictor: ``arroch restrictor``, ``arroch feedback send``, ``arroch constraints ...``.

Exit codes: 0 done (feedback accepted); 1 feedback refused (or does not compile); 2 bad usage or
configuration (site, library, state directory); 3 no answer from a restrictor in time.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
from typing import Any

from protocol.constraint_library import entries_to_wire
from protocol.messages import Constraint, ConstraintSet, FeedbackAck
from protocol.schema import record_to_wire
from runtime.clock import make_clock
from runtime.runner import add_common_arguments, run_service
from runtime.service import Service
from runtime.transport import options_from

from .library import CONSTRAINT, INT, Library, library_for_site, load_library

EXIT_REFUSED = 1
EXIT_CONFIG = 2
EXIT_NO_ANSWER = 3


def _load_site(path: str | None) -> Any:
    from protocol.site import load_site  # the site package is heavy (numpy geometry): load on use

    return load_site(path)


def _add_library_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--library",
        metavar="FILE",
        help="constraint library (TOML) to use instead of the packaged one, e.g. a site-specific library",
    )


def _config_error(exc: Exception) -> int:
    print(f"error: {exc}", file=sys.stderr)
    return EXIT_CONFIG


def _site_and_library(args: argparse.Namespace) -> tuple[Any, Library]:
    return _load_site(args.site), load_library(args.library)


def _client(args: argparse.Namespace, namespace: str, name: str) -> Service:
    """A Zenoh client session on ``namespace``, for one-shot commands."""
    instance = getattr(args, "src", None) or f"{name}-{os.getpid()}"
    if not args.log_level and not os.environ.get("ARROCH_LOG_LEVEL"):
        # A one-shot command's output is its answer; session up/down lines only when asked for.
        logging.getLogger(f"arroch.{name}").setLevel(logging.WARNING)
    return Service(name, namespace, options_from(args), clock=make_clock(args.clock), instance=instance)


class _Unreachable(RuntimeError):
    """No Zenoh session could be opened (e.g. no router at the endpoint)."""


def _open(client: Service) -> None:
    try:
        client.open()
    except Exception as exc:  # zenoh raises its own error types for unreachable endpoints
        raise _Unreachable(f"could not open a Zenoh session: {exc}") from None


# --------------------------------------------------------------------------- arroch restrictor


def _run_restrictor(args: argparse.Namespace) -> int:
    from .service import RestrictorService
    from .store import default_state_dir

    def build() -> RestrictorService:
        site, library = _site_and_library(args)
        namespace = args.namespace or site.name
        return RestrictorService(
            site=site,
            library=library,
            namespace=namespace,
            zenoh_options=options_from(args),
            state_dir=args.state_dir or default_state_dir(namespace),
            clock=make_clock(args.clock),
            max_active=args.max_active,
            fresh=args.fresh,
        )

    return run_service(build)


# --------------------------------------------------------------------------- arroch feedback send


def _pairs(tokens: list[str]) -> list[tuple[str, str | None]]:
    """``--name value --name=value --flag`` -> [(name, value or None), ...]."""
    pairs: list[tuple[str, str | None]] = []
    i = 0
    while i < len(tokens):
        token = tokens[i]
        if not token.startswith("--") or len(token) == 2:
            raise ValueError(f"expected --NAME VALUE after --kind KIND, got {token!r}")
        name, eq, value = token[2:].partition("=")
        if eq:
            pairs.append((name, value))
            i += 1
        elif i + 1 < len(tokens) and not tokens[i + 1].startswith("--"):
            pairs.append((name, tokens[i + 1]))
            i += 2
        else:
            pairs.append((name, None))
            i += 1
    return pairs


def _typed(param_type: str, text: str) -> int | str:
    """The library's type for a command-line value; a value that does not convert is sent as it is
    so the restrictor refuses it with its own reason."""
    if param_type == INT:
        try:
            return int(text)
        except ValueError:
            return text
    return text


def _feedback_send(args: argparse.Namespace) -> int:
    from runtime.feedback_client import send_feedback

    parser: argparse.ArgumentParser = args.parser
    if not args.kind:
        parser.error("--kind needs a library entry id, then its parameters as --NAME VALUE")
    kind = args.kind[0]
    # The command's own options may follow --kind too; whatever they leave are the entry's parameters.
    _, leftovers = parser.parse_known_args(args.kind[1:], namespace=args)
    try:
        pairs = _pairs(leftovers)
        site, library = _site_and_library(args)
    except (ValueError, FileNotFoundError) as exc:
        return _config_error(exc)
    entry = library.get(kind)
    if entry is None:
        return _config_error(
            ValueError(f"unknown constraint kind {kind!r}; the library has: {', '.join(library.entries)}")
        )
    params: dict[str, Any] = {}
    for name, value in pairs:
        param = entry.param(name.replace("-", "_"))
        if param is None:
            parser.error(
                f"--{name} is neither an option of this command nor a parameter of {kind} "
                f"(it takes: {', '.join('--' + n for n in entry.param_names) or 'nothing'})"
            )
        if value is None:
            parser.error(f"--{name} needs a value")
        params[param.name] = _typed(param.type, value)
    try:
        client = _client(args, args.namespace or site.name, "feedback-cli")
        client.keys.feedback_ack(client.src)  # the ack key needs a src usable in a key expression
    except ValueError as exc:
        return _config_error(exc)
    try:
        _open(client)
        ack = send_feedback(client, kind, params, timeout=args.timeout, retry=args.retry)
    except _Unreachable as exc:
        print(exc, file=sys.stderr)
        return EXIT_NO_ANSWER
    finally:
        client.close()
    if ack is None:
        print(f"no answer from a restrictor on {client.keys.feedback()} within {args.timeout:g} s", file=sys.stderr)
        return EXIT_NO_ANSWER
    _print_ack(ack, args.json)
    return 0 if ack.accepted else EXIT_REFUSED


def _print_ack(ack: FeedbackAck, as_json: bool) -> None:
    if as_json:
        print(json.dumps(record_to_wire(ack), sort_keys=True))
    elif ack.accepted:
        print(f"accepted: {ack.reason} (constraints version {ack.constraints_version})")
    else:
        print(f"refused: {ack.reason}")


# --------------------------------------------------------------------------- arroch constraints ...


def _constraints_show(args: argparse.Namespace) -> int:
    from runtime.feedback_client import fetch_constraints

    try:
        namespace = args.namespace or _load_site(args.site).name
    except (ValueError, FileNotFoundError) as exc:
        return _config_error(exc)
    try:
        client = _client(args, namespace, "constraints-cli")
    except ValueError as exc:  # e.g. a namespace that cannot be a key chunk
        return _config_error(exc)
    try:
        _open(client)
        current = fetch_constraints(client, timeout=args.timeout)
    except _Unreachable as exc:
        print(exc, file=sys.stderr)
        return EXIT_NO_ANSWER
    finally:
        client.close()
    if current is None:
        print(f"no restrictor answered on {client.keys.constraints()} within {args.timeout:g} s", file=sys.stderr)
        return EXIT_NO_ANSWER
    print(json.dumps(record_to_wire(current), indent=2, sort_keys=True) if args.json else format_set(current))
    return 0


def format_set(current: ConstraintSet) -> str:
    """A ConstraintSet for people: one line per constraint, then the ASP the planner gets."""
    lines = [f"constraints version {current.version}: {len(current.constraints)} active"]
    lines += [f"  {_format_constraint(c)}" for c in current.constraints]
    if current.asp:
        lines += ["asp:"] + [f"  {line}" for line in current.asp.splitlines()]
    return "\n".join(lines)


def _format_constraint(c: Constraint) -> str:
    params = " ".join(f"{name}={value}" for name, value in c.params.items())
    return f"{c.id}  {c.kind}  {params}  [{c.start:.0f}, {c.end:.0f})  from {c.origin or '?'}"


def _constraints_compile(args: argparse.Namespace) -> int:
    from .compile import Compiled, compile_feedback, describe
    from .validate import Refusal, split_tablet_feedback

    try:
        site, library = _site_and_library(args)
    except (ValueError, FileNotFoundError) as exc:
        return _config_error(exc)
    try:
        try:
            data = json.loads(args.feedback)
        except json.JSONDecodeError as exc:
            raise Refusal(f"feedback is not JSON: {exc}") from None
        kind, params = split_tablet_feedback(data)
        result = compile_feedback(kind, params, library, site, args.now)
    except Refusal as refusal:
        print(json.dumps({"accepted": False, "reason": refusal.reason}) if args.json else f"refused: {refusal.reason}")
        return EXIT_REFUSED
    if isinstance(result, Compiled):
        if args.json:
            print(
                json.dumps(
                    {
                        "accepted": True,
                        "kind": result.kind,
                        "params": result.values,
                        "start": result.start,
                        "end": result.end,
                        "asp": result.asp,
                    }
                )
            )
        else:
            sys.stdout.write(result.asp)
        return 0
    target = next(iter(result.values.values()))
    if args.json:
        print(json.dumps({"accepted": True, "kind": result.entry.id, "params": result.values, "asp": ""}))
    else:
        print(f"{describe(result.entry.id, result.values)}: withdraws {target} from the active set; it adds no ASP")
    return 0


def _constraints_library(args: argparse.Namespace) -> int:
    try:
        site, library = _site_and_library(args)
    except (ValueError, FileNotFoundError) as exc:
        return _config_error(exc)
    entries = library_for_site(site, library)
    if args.json:
        print(json.dumps(entries_to_wire(entries), indent=2))
        return 0
    print(f"constraint library {library.source} on site {site.name}:")
    for entry in entries:
        usable = "" if entry.usable else "  (not usable on this site: no choices)"
        print(f"\n{entry.id}: {entry.label}{usable}\n  {entry.help}")
        for param in entry.params:
            if param.type == INT:
                values = f"{param.min}..{param.max}"
            elif param.type == CONSTRAINT:
                values = "an active constraint id (see `arroch constraints show`)"
            else:
                values = ", ".join(param.choices or []) or "(none on this site)"
            print(f"  --{param.name} ({param.type}): {values}  {param.label}")
        window = entry.window
        if window:
            minutes = f"--{window.param}" if window.param else str(window.minutes)
            print(f"  window: {minutes} minutes from now")
    return 0


# --------------------------------------------------------------------------- registration


def register(sub: argparse._SubParsersAction) -> None:
    run = sub.add_parser(
        "restrictor",
        help="run the restrictor: feedback -> validated ASP constraints, the active set",
        description="Turns feedback chosen from the constraint library into ASP constraints, keeps the active "
        "ConstraintSet (versioned, expiring on the site clock, persisted in --state-dir) and serves it.",
    )
    add_common_arguments(run)
    _add_library_argument(run)
    run.add_argument(
        "--state-dir",
        metavar="DIR",
        help="where the active set is persisted (default $XDG_STATE_HOME/arroch/<namespace>, "
        "i.e. ~/.local/state/arroch/<namespace>)",
    )
    run.add_argument(
        "--max-active", type=int, default=200, metavar="N", help="most active constraints at once (default 200)"
    )
    run.add_argument(
        "--fresh",
        action="store_true",
        help="start with an empty set, forgetting the persisted one (e.g. a new sim mission, whose clock "
        "starts again at 0); the version goes on",
    )
    run.set_defaults(func=_run_restrictor)

    feedback = sub.add_parser("feedback", help="give feedback from the command line (as the tablet does)")
    fsub = feedback.add_subparsers(dest="feedback_command", metavar="ACTION")
    send = fsub.add_parser(
        "send",
        help="send one feedback and wait for its ack",
        allow_abbrev=False,  # --time must not mean --timeout
        description="Send feedback and print the restrictor's answer; retries until acknowledged or --timeout. "
        "Example: arroch feedback send --site FILE --kind door_unavailable --door d_storage --minutes 4. "
        "The parameters after --kind are typed by the library; this command's own options may come "
        "before or after them (an option wins over a parameter of the same name). "
        "Exit 1 if refused, 3 without an answer.",
    )
    add_common_arguments(send)
    _add_library_argument(send)
    send.add_argument("--timeout", type=float, default=10.0, metavar="S", help="give up after S seconds (default 10)")
    send.add_argument(
        "--retry", type=float, default=1.0, metavar="S", help="resend every S seconds until acknowledged (default 1)"
    )
    send.add_argument("--src", metavar="ID", help="sender id (default feedback-cli-<pid>)")
    send.add_argument("--json", action="store_true", help="print the ack as JSON")
    # Not required=True: the options found after --kind are parsed again, without it (see _feedback_send).
    send.add_argument(
        "--kind",
        nargs=argparse.REMAINDER,
        metavar="KIND [--PARAM VALUE ...]",
        help="library entry id, then its parameters (see `arroch constraints library`)",
    )
    send.set_defaults(func=_feedback_send, parser=send)
    feedback.set_defaults(func=lambda _args: feedback.print_help() or EXIT_CONFIG)

    constraints = sub.add_parser("constraints", help="the constraint library and the live constraint set")
    csub = constraints.add_subparsers(dest="constraints_command", metavar="ACTION")
    show = csub.add_parser("show", help="query the live ConstraintSet and print it")
    add_common_arguments(show)
    show.add_argument(
        "--timeout", type=float, default=3.0, metavar="S", help="wait S seconds for the restrictor (default 3)"
    )
    show.add_argument("--json", action="store_true", help="print the set as JSON")
    show.set_defaults(func=_constraints_show)

    comp = csub.add_parser(
        "compile",
        help="offline: validate feedback and print its ASP (exit 1 if refused)",
        description="Validate feedback as the restrictor would and print the ASP it compiles to, or the refusal "
        "(exit 1). A cancel is only checked for shape (there is no live set offline).",
    )
    add_common_arguments(comp, zenoh=False)
    _add_library_argument(comp)
    comp.add_argument(
        "--feedback",
        required=True,
        metavar="JSON",
        help='feedback as the tablet sends it, e.g. {"kind": "door_unavailable", "door": "d_storage", "minutes": 4}',
    )
    comp.add_argument(
        "--now", type=float, default=0.0, metavar="T", help="site-clock time the window starts at (default 0)"
    )
    comp.add_argument("--json", action="store_true", help="print the result as JSON")
    comp.set_defaults(func=_constraints_compile)

    lib = csub.add_parser("library", help="print the constraint library with the site's choices")
    add_common_arguments(lib, zenoh=False)
    _add_library_argument(lib)
    lib.add_argument("--json", action="store_true", help="print it as JSON (the shape the tablet and AR client use)")
    lib.set_defaults(func=_constraints_library)
    constraints.set_defaults(func=lambda _args: constraints.print_help() or EXIT_CONFIG)
