"""What keeps the tablet server to the people meant to use it.

- **Access token**: a fresh random token per run. The page (``/?token=...``), its assets and the
  WebSocket all require it, as the ``token`` query parameter or the cookie the page response sets
  (HttpOnly, Secure, SameSite=Strict), compared in constant time. Without it: HTTP 403.
- **HTTPS**: browsers give the camera only to secure origins (localhost aside), so the server always
  speaks TLS. The certificate is made on first run in the state directory by the deployment's
  certificate helper (:mod:`runtime.certs`): a small authority ``ca.pem``
  (install it on a tablet once to silence the browser's warning for good) and ``tablet.pem`` signed
  by it, naming every address the server announces. Later runs reuse both; the tablet certificate
  alone is remade when an address is new or it is about to expire, so a tablet that trusts the
  authority keeps trusting the server.
- **Origin check**: a WebSocket is accepted only from the page's own origin (``https://<Host>``) or
  an origin given with ``--allow-origin``; a page on another site cannot drive the robots' feedback
  through a tablet's cookie.
- **Rate limits**: :class:`TokenBucket` per client and message class.
"""

from __future__ import annotations

import hmac
import logging
import os
import secrets
import ssl
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from runtime.certs import HostCert, ensure_host_certificate

log = logging.getLogger("arroch.tablet.security")

COOKIE = "arroch_tablet"
TOKEN_BYTES = 18  # 144 bits, 24 URL-safe characters
CERT_NAME = "tablet"
RENEW_BEFORE = 30 * 86400.0  # remake the certificate when it expires within this many seconds


def new_token() -> str:
    return secrets.token_urlsafe(TOKEN_BYTES)


def token_matches(expected: str, query: Mapping[str, str], cookies: Mapping[str, str]) -> bool:
    """The request carries ``expected`` as its ``token`` parameter or, without one, its cookie.

    A token in the URL is the credential the user presented: a wrong one is refused even when the
    browser still holds a valid cookie from an earlier visit. Compared in constant time."""
    candidate = query.get("token") if "token" in query else cookies.get(COOKIE)
    return candidate is not None and hmac.compare_digest(candidate.encode("utf-8", "replace"), expected.encode())


def origin_allowed(origin: str | None, host: str | None, scheme: str, extra: Iterable[str] = ()) -> bool:
    """The WebSocket's ``Origin`` is the page's own origin (``scheme://Host``) or one allowed explicitly.

    A missing Origin is refused: every browser sends one on a WebSocket handshake, and a non-browser
    client can set it like any other header, so there is no reason to let it off."""
    if not origin or not host:
        return False
    origin = origin.rstrip("/").lower()
    return origin == f"{scheme}://{host}".lower() or origin in {o.rstrip("/").lower() for o in extra}


class TokenBucket:
    """At most ``rate`` events per second on average, ``burst`` at once."""

    def __init__(self, rate: float, burst: float) -> None:
        self.rate = rate
        self.burst = burst
        self._tokens = burst
        self._last = time.monotonic()

    def take(self, n: float = 1.0) -> bool:
        now = time.monotonic()
        self._tokens = min(self.burst, self._tokens + (now - self._last) * self.rate)
        self._last = now
        if self._tokens >= n:
            self._tokens -= n
            return True
        return False


# --------------------------------------------------------------------------- certificate


def default_state_dir() -> Path:
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "arroch" / "tablet"


@dataclass(frozen=True)
class Certificate:
    cert: Path
    key: Path
    authority: Path
    made: bool  # True when this run (re)made the tablet certificate


def ensure_certificate(directory: Path, dns: Iterable[str], ips: Iterable[str]) -> Certificate:
    """The tablet certificate in ``directory`` naming ``dns`` and ``ips``, made or remade as needed.

    Raises :class:`runtime.certs.CertError` when the files cannot be made or read.
    """
    directory = Path(directory)
    dns_names = list(dict.fromkeys(["localhost", *dns]))
    ip_names = list(dict.fromkeys(["127.0.0.1", *ips]))
    made = ensure_host_certificate(
        directory, HostCert(CERT_NAME, dns=dns_names, ips=ip_names), renew_before=RENEW_BEFORE
    )
    return Certificate(
        cert=directory / f"{CERT_NAME}.pem",
        key=directory / f"{CERT_NAME}.key",
        authority=directory / "ca.pem",
        made=made,
    )


def server_ssl_context(certificate: Certificate) -> ssl.SSLContext:
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    context.minimum_version = ssl.TLSVersion.TLSv1_2
    context.load_cert_chain(str(certificate.cert), str(certificate.key))
    return context
