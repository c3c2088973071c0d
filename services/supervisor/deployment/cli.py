"""``arroch deploy certs | render | acl``: the files a multi-machine deployment needs.

    arroch deploy certs  --out DIR --hosts router,planner,restrictor,sim,ar,supervisor --san router=10.0.0.1
    arroch deploy render --profile secure --role planner --certs DIR --router tls/10.0.0.1:7447 --out planner.json5
    arroch deploy render --profile secure --role all --certs DIR --router tls/10.0.0.1:7447 --out-dir zenoh/
    arroch deploy acl    (prints the router's access-control block)

See docs/deploy.md for which file goes to which machine.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from runtime.certs import CertError, make_certs, parse_hosts

from . import acl
from .render import KINDS, PROFILES, TEMPLATE_DIR, RenderError, Request, render

log = logging.getLogger("arroch.deploy")


def _split(text: str | None) -> list[str]:
    return [part.strip() for part in (text or "").split(",") if part.strip()]


def run_certs(args: argparse.Namespace) -> int:
    try:
        hosts = parse_hosts(_split(args.hosts), args.san or [], localhost=not args.no_localhost)
        for line in make_certs(Path(args.out), hosts, days=args.days, force=args.force):
            print(line)
    except (CertError, OSError) as exc:  # OSError: an --out that is a file, a folder we may not write
        log.error("%s", exc)
        return 2
    print(f"keep {Path(args.out) / 'ca.key'} off the robots and tablets: it signs new identities")
    return 0


def run_render(args: argparse.Namespace) -> int:
    every_role = [*acl.ROLES, *acl.INFRASTRUCTURE]
    roles = every_role if args.role == "all" else _split(args.role)
    if not roles:
        log.error("--role needs at least one role (%s, or all)", ", ".join(every_role))
        return 2
    if len(roles) > 1 and not args.out_dir:
        log.error("several roles (%s) need --out-dir DIR (one <role>.json5 each)", ", ".join(roles))
        return 2
    if args.name and len(roles) > 1:
        log.error("--name picks one certificate: give a single --role with it")
        return 2
    try:
        extra_cns = acl.parse_common_names(args.cn or [])
        texts = {}
        for role in roles:
            request = Request(
                profile=args.profile,
                role=role,
                kind=None if role == "router" else args.kind,
                certs=Path(args.certs) if args.certs else None,
                name=args.name,
                connect=[] if role == "router" else _split(args.router),
                listen=_split(args.listen) if role == "router" or args.kind == "peer" else [],
                extra_cns=extra_cns,
                check_files=not args.no_check_files,
            )
            texts[role] = render(request, Path(args.templates))
    except (RenderError, ValueError) as exc:
        log.error("%s", exc)
        return 2
    try:
        if args.out_dir:
            out_dir = Path(args.out_dir)
            out_dir.mkdir(parents=True, exist_ok=True)
            for role, text in texts.items():
                path = out_dir / f"{role}.json5"
                path.write_text(text)
                print(f"wrote {path}")
        elif args.out in (None, "-"):
            sys.stdout.write(next(iter(texts.values())))
        else:
            Path(args.out).write_text(next(iter(texts.values())))
            print(f"wrote {args.out}")
    except OSError as exc:
        log.error("cannot write: %s", exc)
        return 2
    return 0


def run_acl(args: argparse.Namespace) -> int:
    try:
        print(acl.to_json5(acl.parse_common_names(args.cn or [])))
    except ValueError as exc:
        log.error("%s", exc)
        return 2
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "deploy",
        help="deployment files: TLS certificates, per-host Zenoh configs, access control",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    actions = parser.add_subparsers(dest="deploy_command", metavar="ACTION", required=True)

    certs = actions.add_parser(
        "certs", help="make a CA (or reuse the one in --out) and a certificate + key per identity"
    )
    certs.add_argument(
        "--out", required=True, metavar="DIR", help="directory for ca.pem/ca.key and <name>.pem/<name>.key"
    )
    certs.add_argument(
        "--hosts",
        required=True,
        metavar="NAMES",
        help="comma-separated identities; the name is the certificate's common name, i.e. its role "
        f"({', '.join((*acl.ROLES, *acl.INFRASTRUCTURE))}; extra names need --cn when rendering the router)",
    )
    certs.add_argument(
        "--san",
        action="append",
        metavar="NAME=ADDR[,ADDR]",
        help="IP addresses or DNS names NAME is reached at (repeatable); the router's must include what clients dial",
    )
    certs.add_argument("--days", type=int, default=825, help="validity of host certificates in days (default 825)")
    certs.add_argument(
        "--no-localhost", action="store_true", help="do not add localhost/127.0.0.1 to every certificate"
    )
    certs.add_argument(
        "--force", action="store_true", help="remake host certificates that exist (the CA is always kept)"
    )
    certs.set_defaults(func=run_certs)

    rend = actions.add_parser(
        "render", help="write a checked Zenoh JSON5 config for a role from deploy/zenoh templates"
    )
    rend.add_argument(
        "--profile",
        choices=PROFILES,
        default="secure",
        help="plain (TCP) or secure (TLS, mTLS, access control); default secure",
    )
    rend.add_argument(
        "--role", required=True, help="router, planner, restrictor, sim, ar, supervisor; comma-separated, or all"
    )
    rend.add_argument(
        "--kind", choices=KINDS[1:], default="client", help="Zenoh mode of a service: client (default) or peer"
    )
    rend.add_argument(
        "--certs", metavar="DIR", help="certificate directory as seen on the target host (secure profile)"
    )
    rend.add_argument("--name", help="certificate to present (default: the role), e.g. ar-2 for a second tablet")
    rend.add_argument("--router", metavar="ENDPOINTS", help="router endpoint(s) services dial, e.g. tls/10.0.0.1:7447")
    rend.add_argument(
        "--listen",
        metavar="ENDPOINTS",
        help="endpoints the router (or a peer) listens on (router default: all interfaces, port 7447)",
    )
    rend.add_argument(
        "--cn",
        action="append",
        metavar="ROLE=NAME[,NAME]",
        help="more certificate names for a role in the router's rules (repeatable)",
    )
    rend.add_argument(
        "--no-check-files", action="store_true", help="do not require the certificate files to exist here"
    )
    rend.add_argument(
        "--templates", default=str(TEMPLATE_DIR), metavar="DIR", help=f"template directory (default {TEMPLATE_DIR})"
    )
    out = rend.add_mutually_exclusive_group()
    out.add_argument("--out", metavar="FILE", help="output file for one role (default: stdout)")
    out.add_argument("--out-dir", metavar="DIR", help="output directory: one <role>.json5 per role")
    rend.set_defaults(func=run_render)

    show = actions.add_parser("acl", help="print the router's access-control block (JSON5, commented)")
    show.add_argument("--cn", action="append", metavar="ROLE=NAME[,NAME]", help="more certificate names for a role")
    show.set_defaults(func=run_acl)
