"""``arroch deploy certs``: a private certificate authority and one certificate per identity.

Zenoh's TLS transport (rustls) authenticates both ends when ``enable_mtls`` is on: the router
proves it is the router (its certificate must name the address clients dial, as a subjectAltName)
and every client proves who it is. The client certificate's common name is the identity the
router's access-control rules name (``planner``, ``sim``, ``ar``, ...), so the CN is the role, and
one certificate is made per service identity rather than per machine.

The files are made with the ``openssl`` command line (present on every Linux and macOS host),
so the project needs no extra Python dependency for them:

    DIR/ca.pem, DIR/ca.key              the authority (keep ca.key off the robots and tablets)
    DIR/<name>.pem, DIR/<name>.key      one pair per identity, signed by the authority

An existing authority in DIR is reused, so adding a host later signs it with the same CA; existing
host pairs are kept unless ``force`` is set. Keys are EC P-256 (PKCS#8), written mode 0600.
"""

from __future__ import annotations

import ipaddress
import logging
import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

log = logging.getLogger("arroch.deploy.certs")

CA_NAME = "ca"
CA_COMMON_NAME = "ARROCH deployment CA"
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,62}$")
_DNS = re.compile(r"^[A-Za-z0-9*]([A-Za-z0-9\-.]{0,251}[A-Za-z0-9])?$")


class CertError(RuntimeError):
    """A certificate could not be made or checked; the message says why."""


@dataclass
class HostCert:
    """One identity to certify: its common name and the addresses it may be reached at."""

    name: str
    dns: list[str] = field(default_factory=list)
    ips: list[str] = field(default_factory=list)

    def subject_alt_names(self) -> str:
        entries = [f"DNS:{d}" for d in self.dns] + [f"IP:{ip}" for ip in self.ips]
        return ",".join(entries)


def parse_hosts(names: list[str], sans: list[str], *, localhost: bool = True) -> list[HostCert]:
    """Hosts from ``--hosts a,b`` and ``--san a=10.0.0.1,a.lan`` (IP addresses and DNS names).

    Every certificate also names itself (``DNS:<name>``) and, unless ``localhost`` is False,
    ``localhost``/``127.0.0.1``, so a service on the router's own machine can dial it locally.
    """
    hosts: dict[str, HostCert] = {}
    for name in names:
        if not _NAME.match(name):
            raise CertError(f"host name {name!r}: use letters, digits, '.', '_' and '-' (at most 63)")
        if name == CA_NAME:
            raise CertError(f"host name {name!r} is reserved for the authority's own files")
        host = hosts.setdefault(name, HostCert(name))
        host.dns.append(name)
        if localhost:
            host.dns.append("localhost")
            host.ips.append("127.0.0.1")
    for entry in sans:
        name, sep, addresses = entry.partition("=")
        if not sep or not addresses:
            raise CertError(f"--san {entry!r}: expected NAME=ADDRESS[,ADDRESS...]")
        if name not in hosts:
            raise CertError(f"--san {entry!r}: {name!r} is not one of the --hosts ({', '.join(hosts) or 'none'})")
        for address in filter(None, (a.strip() for a in addresses.split(","))):
            try:
                hosts[name].ips.append(str(ipaddress.ip_address(address)))
            except ValueError:
                if not _DNS.match(address):
                    raise CertError(f"--san {entry!r}: {address!r} is neither an IP address nor a DNS name") from None
                hosts[name].dns.append(address)
    for host in hosts.values():
        host.dns = list(dict.fromkeys(host.dns))
        host.ips = list(dict.fromkeys(host.ips))
    if not hosts:
        raise CertError("no hosts given (e.g. --hosts router,planner,restrictor,sim,ar)")
    return list(hosts.values())


def _openssl() -> str:
    path = shutil.which("openssl")
    if path is None:
        raise CertError(
            "the 'openssl' command is needed to make certificates; install it (Debian: apt-get install openssl)"
        )
    return path


def _run(*args: str) -> str:
    result = subprocess.run([_openssl(), *args], capture_output=True, text=True)
    if result.returncode != 0:
        raise CertError(f"openssl {args[0]} failed: {result.stderr.strip() or result.stdout.strip()}")
    return result.stdout


def _new_key(path: Path) -> None:
    # Created 0600 before any byte is written, so the key is never readable by others.
    _run("genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256", "-out", str(path))
    os.chmod(path, 0o600)


def _make_ca(directory: Path, days: int) -> None:
    key, cert = directory / f"{CA_NAME}.key", directory / f"{CA_NAME}.pem"
    _new_key(key)
    _run(
        "req",
        "-x509",
        "-new",
        "-key",
        str(key),
        "-out",
        str(cert),
        "-days",
        str(days),
        "-sha256",
        "-subj",
        f"/CN={CA_COMMON_NAME}",
        "-addext",
        "basicConstraints=critical,CA:TRUE,pathlen:0",
        "-addext",
        "keyUsage=critical,keyCertSign,cRLSign",
        "-addext",
        "subjectKeyIdentifier=hash",
    )


def _make_host(directory: Path, host: HostCert, days: int) -> None:
    key, cert = directory / f"{host.name}.key", directory / f"{host.name}.pem"
    _new_key(key)
    # rustls (webpki) wants a v3 end-entity certificate: not a CA, the names in subjectAltName
    # (the CN is never used for name checks), and both TLS usages, since a service is a TLS
    # client of the router while the router is a TLS server (and a client of other routers).
    extensions = "\n".join(
        [
            "basicConstraints=critical,CA:FALSE",
            "keyUsage=critical,digitalSignature",
            "extendedKeyUsage=serverAuth,clientAuth",
            f"subjectAltName={host.subject_alt_names()}",
            "subjectKeyIdentifier=hash",
            "authorityKeyIdentifier=keyid",
        ]
    )
    with tempfile.TemporaryDirectory() as tmp:
        csr, ext = Path(tmp) / "host.csr", Path(tmp) / "host.ext"
        ext.write_text(extensions + "\n")
        _run("req", "-new", "-key", str(key), "-out", str(csr), "-subj", f"/CN={host.name}")
        _run(
            "x509",
            "-req",
            "-in",
            str(csr),
            "-CA",
            str(directory / f"{CA_NAME}.pem"),
            "-CAkey",
            str(directory / f"{CA_NAME}.key"),
            # A random positive 127-bit serial: no serial file to keep next to the authority.
            "-set_serial",
            str(int.from_bytes(os.urandom(16), "big") >> 1),
            "-out",
            str(cert),
            "-days",
            str(days),
            "-sha256",
            "-extfile",
            str(ext),
        )
    verify(directory, host.name)


def verify(directory: Path, name: str) -> None:
    """Check that ``<name>.pem`` chains to the authority in ``directory``."""
    out = _run("verify", "-CAfile", str(directory / f"{CA_NAME}.pem"), str(directory / f"{name}.pem"))
    if "OK" not in out:
        raise CertError(f"{name}.pem does not verify against {CA_NAME}.pem: {out.strip()}")


def describe(directory: Path, name: str) -> str:
    """``CN=... ; names ...`` of one certificate, for the summary printed to the operator."""
    text = _run(
        "x509", "-in", str(directory / f"{name}.pem"), "-noout", "-subject", "-ext", "subjectAltName", "-enddate"
    )
    lines = [line.strip() for line in text.splitlines() if line.strip() and "X509v3" not in line]
    return "; ".join(lines)


def make_certs(
    directory: Path, hosts: list[HostCert], *, days: int = 825, ca_days: int = 3650, force: bool = False
) -> list[str]:
    """Make (or reuse) the authority and a pair per host; returns one summary line per file set."""
    directory.mkdir(parents=True, exist_ok=True)
    summary: list[str] = []
    ca_key, ca_cert = directory / f"{CA_NAME}.key", directory / f"{CA_NAME}.pem"
    if ca_cert.exists() != ca_key.exists():
        raise CertError(
            f"{directory} holds only one of {CA_NAME}.pem and {CA_NAME}.key: restore the other or remove both"
        )
    if ca_cert.exists():
        summary.append(f"{ca_cert}: kept the existing authority")
    else:
        _make_ca(directory, ca_days)
        summary.append(f"{ca_cert}: new authority ({describe(directory, CA_NAME)})")
    for host in hosts:
        cert = directory / f"{host.name}.pem"
        if cert.exists() and not force:
            verify(directory, host.name)
            summary.append(f"{cert}: kept (use --force to remake)")
            continue
        _make_host(directory, host, days)
        summary.append(f"{cert}: {describe(directory, host.name)}")
    return summary
