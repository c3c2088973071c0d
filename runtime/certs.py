"""Certificates for the deployment and the tablet page: a private authority and one pair per identity.

Zenoh's TLS transport (rustls) authenticates both ends when ``enable_mtls`` is on: the router
proves it is the router (its certificate must name the address clients dial, as a subjectAltName)
and every client proves who it is. The client certificate's common name is the identity the
router's access-control rules name (``planner``, ``sim``, ``ar``, ...), so the CN is the role, and
one certificate is made per service identity rather than per machine. The tablet page's HTTPS
certificate (``arroch tablet``) is made the same way, as the identity ``tablet``.

Everything is done in-process with ``cryptography`` (no ``openssl`` command needed):

    DIR/ca.pem, DIR/ca.key              the authority (keep ca.key off the robots and tablets)
    DIR/<name>.pem, DIR/<name>.key      one pair per identity, signed by the authority

An existing authority in DIR is reused, so adding a host later signs it with the same CA; existing
host pairs are kept unless ``force`` is set. Keys are EC P-256 (PKCS#8 PEM), written mode 0600.
"""

from __future__ import annotations

import datetime
import ipaddress
import logging
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

log = logging.getLogger("arroch.certs")

CA_NAME = "ca"
CA_COMMON_NAME = "ARROCH deployment CA"
# Certificates start an hour in the past, so a machine whose clock lags a little still accepts them.
BACKDATE = datetime.timedelta(hours=1)
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

    def subject_alt_names(self) -> list[x509.GeneralName]:
        return [x509.DNSName(d) for d in self.dns] + [x509.IPAddress(ipaddress.ip_address(ip)) for ip in self.ips]


@dataclass(frozen=True)
class CertInfo:
    """What one certificate says: its common name, the names it may serve, its validity."""

    common_name: str
    dns: tuple[str, ...]
    ips: tuple[str, ...]
    not_after: datetime.datetime  # UTC

    @property
    def names(self) -> set[str]:
        return set(self.dns) | set(self.ips)

    def __str__(self) -> str:
        names = [f"DNS:{d}" for d in self.dns] + [f"IP:{ip}" for ip in self.ips]
        alt = f"; {', '.join(names)}" if names else ""
        return f"CN={self.common_name}{alt}; valid until {self.not_after:%Y-%m-%d %H:%M} UTC"


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


# --------------------------------------------------------------------------- files


def _write_private(path: Path, data: bytes) -> None:
    # Created 0600 before any byte is written, so the key is never readable by others.
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as out:
        out.write(data)
    os.chmod(path, 0o600)  # an existing file keeps its old mode through O_CREAT


def _new_key(path: Path) -> ec.EllipticCurvePrivateKey:
    key = ec.generate_private_key(ec.SECP256R1())
    pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption())
    _write_private(path, pem)
    return key


def load_certificate(path: Path) -> x509.Certificate:
    """The PEM certificate at ``path``; :class:`CertError` naming the file when it cannot be read."""
    try:
        return x509.load_pem_x509_certificate(Path(path).read_bytes())
    except (OSError, ValueError) as exc:
        raise CertError(f"{path}: not a readable PEM certificate ({exc})") from None


def _load_key(path: Path) -> ec.EllipticCurvePrivateKey:
    try:
        key = serialization.load_pem_private_key(Path(path).read_bytes(), password=None)
    except (OSError, ValueError, TypeError) as exc:
        raise CertError(f"{path}: not a readable unencrypted PEM private key ({exc})") from None
    if not isinstance(key, ec.EllipticCurvePrivateKey):
        raise CertError(f"{path}: expected an EC private key, got {type(key).__name__}")
    return key


def _subject(common_name: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _validity(builder: x509.CertificateBuilder, days: int) -> x509.CertificateBuilder:
    now = datetime.datetime.now(datetime.UTC)
    return builder.not_valid_before(now - BACKDATE).not_valid_after(now + datetime.timedelta(days=days))


def _make_ca(directory: Path, days: int) -> None:
    key = _new_key(directory / f"{CA_NAME}.key")
    name = _subject(CA_COMMON_NAME)
    builder = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=False,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
    )
    cert = _validity(builder, days).sign(key, hashes.SHA256())
    (directory / f"{CA_NAME}.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))


def _make_host(directory: Path, host: HostCert, days: int) -> None:
    ca_cert = load_certificate(directory / f"{CA_NAME}.pem")
    ca_key = _load_key(directory / f"{CA_NAME}.key")
    key = _new_key(directory / f"{host.name}.key")
    # rustls (webpki) wants a v3 end-entity certificate: not a CA, the names in subjectAltName
    # (the CN is never used for name checks), and both TLS usages, since a service is a TLS
    # client of the router while the router is a TLS server (and a client of other routers).
    builder = (
        x509.CertificateBuilder()
        .subject_name(_subject(host.name))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=False,
                crl_sign=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(
            x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False
        )
        .add_extension(x509.SubjectAlternativeName(host.subject_alt_names()), critical=False)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False)
    )
    cert = _validity(builder, days).sign(ca_key, hashes.SHA256())
    (directory / f"{host.name}.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    verify(directory, host.name)


# --------------------------------------------------------------------------- checks


def verify(directory: Path, name: str) -> None:
    """Check that ``<name>.pem`` was signed by the authority in ``directory`` and is valid now."""
    ca_cert = load_certificate(directory / f"{CA_NAME}.pem")
    cert = load_certificate(directory / f"{name}.pem")
    try:
        cert.verify_directly_issued_by(ca_cert)
    except (ValueError, TypeError, InvalidSignature) as exc:
        raise CertError(f"{name}.pem does not verify against {CA_NAME}.pem: {exc or 'bad signature'}") from None
    now = datetime.datetime.now(datetime.UTC)
    if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
        raise CertError(
            f"{name}.pem is valid only from {cert.not_valid_before_utc:%Y-%m-%d %H:%M} "
            f"to {cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC"
        )


def info(path: Path) -> CertInfo:
    """The common name, subjectAltNames and expiry of the certificate at ``path``."""
    cert = load_certificate(path)
    common = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    try:
        alt = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        dns = tuple(alt.get_values_for_type(x509.DNSName))
        ips = tuple(str(ip) for ip in alt.get_values_for_type(x509.IPAddress))
    except x509.ExtensionNotFound:
        dns, ips = (), ()
    return CertInfo(
        common_name=str(common[0].value) if common else "", dns=dns, ips=ips, not_after=cert.not_valid_after_utc
    )


def describe(directory: Path, name: str) -> str:
    """``CN=...; names ...; valid until ...`` of one certificate, for the summary printed to the operator."""
    return str(info(directory / f"{name}.pem"))


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


def ensure_host_certificate(directory: Path, host: HostCert, *, renew_before: float) -> bool:
    """``<host.name>.pem`` in ``directory`` naming every address of ``host``, made or remade as needed.

    The authority is kept (a tablet that trusts it keeps trusting the server); the host pair is
    remade when it is missing, unreadable, does not chain to the authority, lacks a name, or expires
    within ``renew_before`` seconds. Returns True when this call made the pair.
    """
    cert = directory / f"{host.name}.pem"
    force = False
    if cert.exists():
        try:
            verify(directory, host.name)
            current = info(cert)
        except CertError as exc:  # unreadable or foreign: make a new one rather than serve a broken file
            log.warning("%s cannot be used (%s); making a new certificate", cert, exc)
            force = True
        else:
            missing = set(host.dns + host.ips) - current.names
            left = (current.not_after - datetime.datetime.now(datetime.UTC)).total_seconds()
            if missing or left < renew_before:
                why = f"it does not name {', '.join(sorted(missing))}" if missing else "it expires soon"
                log.info("remaking %s: %s", cert, why)
                force = True
    made = force or not cert.exists()
    for line in make_certs(directory, [host], force=force):
        log.debug("%s", line)
    return made
