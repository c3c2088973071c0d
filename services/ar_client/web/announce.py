"""Where a tablet should point its browser: the page's URLs with the token, and a QR code of one.

With ``--host 0.0.0.0`` (every interface) the URLs use this machine's name and its IPv4 addresses
as the resolver knows them, loopback last; ``--public-host`` puts a name or address of your choice
first (e.g. when the tablet reaches the server through a name the machine does not know itself).
The certificate names all of them (:func:`certificate_names`), so none gives a name mismatch.
"""

from __future__ import annotations

import ipaddress
import logging
import socket
import sys
from typing import TextIO

log = logging.getLogger("arroch.tablet")

ANY = ("", "0.0.0.0", "::")


def _is_ip(text: str) -> bool:
    try:
        ipaddress.ip_address(text)
        return True
    except ValueError:
        return False


def machine_addresses() -> list[str]:
    """This machine's IPv4 addresses known to its resolver, loopback last (no network traffic)."""
    found: list[str] = []
    try:
        for info in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET, socket.SOCK_STREAM):
            found.append(str(info[4][0]))
    except OSError:
        pass
    found = list(dict.fromkeys(found))
    return [a for a in found if not a.startswith("127.")] + ["127.0.0.1"]


def hosts_to_announce(host: str, public_host: str | None = None) -> list[str]:
    """The host names/addresses to put in URLs, best first."""
    hosts = [public_host] if public_host else []
    if host in ANY:
        hosts += machine_addresses()
    else:
        hosts.append(host)
    return list(dict.fromkeys(hosts))


def certificate_names(hosts: list[str]) -> tuple[list[str], list[str]]:
    """(DNS names, IP addresses) the certificate must carry for these hosts (plus the machine's name)."""
    dns = [socket.gethostname()] + [h for h in hosts if not _is_ip(h)]
    ips = [h for h in hosts if _is_ip(h)]
    return list(dict.fromkeys(dns)), list(dict.fromkeys(ips))


def page_url(host: str, port: int, token: str, mode: str | None = None) -> str:
    shown = f"[{host}]" if ":" in host else host
    query = f"?token={token}" + (f"&mode={mode}" if mode else "")
    return f"https://{shown}:{port}/{query}"


def announce(urls: list[str], out: TextIO = sys.stdout, qr: bool = True) -> None:
    """Print the URLs and, for the first one, a QR code a tablet's camera app can open."""
    # One write per line: unbuffered, print() writes the text and its newline apart, and a log
    # line from another thread on the same pipe can land between them, inside the URL's line.
    out.write("Tablet page (the token in it is this run's access key; share it only with the tablet):\n")
    for url in urls:
        out.write(f"  {url}\n")
    if qr and urls:
        try:
            import segno
        except ImportError:
            log.warning("no QR code: the 'segno' package is not installed")
        else:
            segno.make(urls[0], error="m").terminal(out=out, compact=True)
    out.flush()
