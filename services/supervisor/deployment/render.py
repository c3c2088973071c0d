"""``arroch deploy render``: per-host Zenoh configs from the templates in ``deploy/zenoh/``.

A template is commented JSON5 with ``${NAME}`` holes (``LISTEN``, ``CONNECT``, ``CA``, ``CERT``,
``KEY``, ``ACCESS_CONTROL``). Each hole is filled with a JSON value, so quoting is never done by
hand, and the result is parsed back with Zenoh's own config parser and checked field by field
before it is written: a file this command writes is one Zenoh accepts, naming the files it meant.
"""

from __future__ import annotations

import json
import string
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from runtime.certs import CA_NAME, CertError, verify

from . import acl

PROFILES = ("plain", "secure")
KINDS = ("router", "peer", "client")
DEFAULT_PORT = 7447
# deploy/ sits at the top of the source tree, beside services/.
TEMPLATE_DIR = Path(__file__).resolve().parents[3] / "deploy" / "zenoh"


class RenderError(ValueError):
    """The request cannot give a valid config; the message says what to change."""


@dataclass
class Request:
    """One config to render. ``name`` is the certificate to present (default: the role)."""

    profile: str
    role: str
    kind: str | None = None
    certs: Path | None = None
    name: str | None = None
    connect: list[str] = field(default_factory=list)
    listen: list[str] = field(default_factory=list)
    extra_cns: dict[str, list[str]] = field(default_factory=dict)
    check_files: bool = True

    @property
    def resolved_kind(self) -> str:
        return self.kind or ("router" if self.role == "router" else "client")

    @property
    def protocol(self) -> str:
        return "tls" if self.profile == "secure" else "tcp"


def normalise_endpoints(endpoints: list[str], protocol: str) -> list[str]:
    """``10.0.0.1:7447`` → ``tls/10.0.0.1:7447`` (or tcp/); the secure profile refuses non-TLS ones."""
    out = []
    for endpoint in endpoints:
        endpoint = endpoint.strip()
        if not endpoint:
            continue
        if "/" not in endpoint:
            endpoint = f"{protocol}/{endpoint}"
        scheme, _, address = endpoint.partition("/")
        if protocol == "tls" and scheme != "tls":
            raise RenderError(f"endpoint {endpoint!r}: the secure profile speaks TLS only (use tls/{address})")
        if ":" not in address:
            raise RenderError(f"endpoint {endpoint!r} has no port (e.g. {scheme}/{address}:{DEFAULT_PORT})")
        out.append(endpoint)
    return out


def _tls_files(req: Request) -> dict[str, str]:
    if req.certs is None:
        raise RenderError("the secure profile needs --certs DIR (made by arroch deploy certs)")
    directory = req.certs.expanduser().resolve()
    name = req.name or req.role
    files = {"CA": directory / f"{CA_NAME}.pem", "CERT": directory / f"{name}.pem", "KEY": directory / f"{name}.key"}
    if req.check_files:
        missing = [str(path) for path in files.values() if not path.is_file()]
        if missing:
            raise RenderError(
                f"missing {', '.join(missing)} (make them with: arroch deploy certs --out {directory} --hosts {name}; "
                "or pass --no-check-files when rendering for another machine's layout)"
            )
        try:
            verify(directory, name)
        except CertError as exc:
            raise RenderError(str(exc)) from None
    return {hole: str(path) for hole, path in files.items()}


def values_for(req: Request) -> dict[str, object]:
    """The value of every hole of the request's template."""
    if req.profile not in PROFILES:
        raise RenderError(f"profile {req.profile!r} is not one of {', '.join(PROFILES)}")
    if req.role not in (*acl.ROLES, *acl.INFRASTRUCTURE):
        raise RenderError(
            f"role {req.role!r} is not one of {', '.join((*acl.ROLES, *acl.INFRASTRUCTURE))} "
            "(a certificate with another name is chosen with --name)"
        )
    if req.resolved_kind not in KINDS:
        raise RenderError(f"kind {req.kind!r} is not one of {', '.join(KINDS)}")
    kind = req.resolved_kind
    values: dict[str, object] = {}
    connect = normalise_endpoints(req.connect, req.protocol)
    listen = normalise_endpoints(req.listen, req.protocol)
    if kind == "router":
        values["LISTEN"] = listen or [f"{req.protocol}/0.0.0.0:{DEFAULT_PORT}"]
        if connect:
            raise RenderError("a router config takes --listen; other routers are not dialled by these templates")
    else:
        if not connect:
            raise RenderError(f"a {kind} needs --router ENDPOINT (e.g. {req.protocol}/10.0.0.1:{DEFAULT_PORT})")
        values["CONNECT"] = connect
        if kind == "peer":
            values["LISTEN"] = listen
        elif listen:
            raise RenderError("a client does not listen; use --kind peer to accept direct links")
    if req.profile == "secure":
        values.update(_tls_files(req))
        if kind == "router":
            # Indented to sit one level deep in the template's top-level object.
            block = acl.to_json5(req.extra_cns).splitlines()
            values["ACCESS_CONTROL"] = "\n".join([block[0], *("  " + line for line in block[1:])])
    return values


def template_path(req: Request, template_dir: Path = TEMPLATE_DIR) -> Path:
    suffix = "-secure" if req.profile == "secure" else ""
    path = template_dir / f"{req.resolved_kind}{suffix}.json5"
    if not path.is_file():
        raise RenderError(f"template {path} not found (run from a source checkout, or pass --templates DIR)")
    return path


def render(req: Request, template_dir: Path = TEMPLATE_DIR) -> str:
    """The filled-in, checked config text."""
    values = values_for(req)
    text = template_path(req, template_dir).read_text()
    # The access-control block is already JSON5 text; every other value is encoded as JSON.
    encoded = {hole: (value if hole == "ACCESS_CONTROL" else json.dumps(value)) for hole, value in values.items()}
    try:
        rendered = string.Template(text).substitute(encoded)
    except KeyError as exc:
        raise RenderError(
            f"template {template_path(req, template_dir).name} needs {exc} which a {req.resolved_kind} request does "
            "not give"
        ) from None
    except ValueError as exc:  # a stray '$' in the template
        raise RenderError(
            f"template {template_path(req, template_dir).name}: {exc} (write a literal $ as $$)"
        ) from None
    check(rendered, req, values)
    return rendered


def check(text: str, req: Request, values: dict[str, object]) -> None:
    """Parse with Zenoh and compare what it read with what was meant."""
    try:
        config = zenoh.Config.from_json5(text)
    except Exception as exc:
        raise RenderError(f"Zenoh refuses the rendered config: {exc}") from None
    expected = {"mode": req.resolved_kind}
    if "LISTEN" in values:
        expected["listen/endpoints"] = values["LISTEN"]
    if "CONNECT" in values:
        expected["connect/endpoints"] = values["CONNECT"]
    if req.profile == "secure":
        expected["transport/link/tls/root_ca_certificate"] = values["CA"]
        expected["transport/link/tls/enable_mtls"] = True
        cert_key = "listen" if req.resolved_kind == "router" else "connect"
        expected[f"transport/link/tls/{cert_key}_certificate"] = values["CERT"]
        expected[f"transport/link/tls/{cert_key}_private_key"] = values["KEY"]
        if req.resolved_kind == "router":
            expected["access_control/enabled"] = True
    for path, want in expected.items():
        got = json.loads(config.get_json(path))
        if got != want:
            raise RenderError(
                f"rendered config has {path} = {got!r}, expected {want!r} (template out of step with render.py?)"
            )
