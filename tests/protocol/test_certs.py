"""Certificates made in-process (runtime.certs): real TLS handshakes with them, and what is refused.

A foreign authority (``trustme``) stands for certificates someone else made: they must not pass
:func:`verify`, must not be accepted by a server trusting our authority, and a tablet certificate
signed by one is remade rather than served.
"""

from __future__ import annotations

import socket
import ssl
import threading
from pathlib import Path

import pytest
import trustme

from runtime.certs import CertError, HostCert, describe, ensure_host_certificate, info, make_certs, parse_hosts, verify


def _handshake(server: ssl.SSLContext, client: ssl.SSLContext, hostname: str) -> dict:
    """One TLS handshake over loopback; the server's view of the client certificate (or the error)."""
    listener = socket.create_server(("127.0.0.1", 0))
    seen: dict = {}

    def serve() -> None:
        conn, _ = listener.accept()
        try:
            with server.wrap_socket(conn, server_side=True) as tls:
                seen["peer"] = tls.getpeercert()
                tls.sendall(b"ok")
        except (ssl.SSLError, OSError) as exc:
            seen["error"] = exc

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        with socket.create_connection(listener.getsockname(), timeout=5) as raw:
            with client.wrap_socket(raw, server_hostname=hostname) as tls:
                seen["reply"] = tls.recv(2)
    finally:
        thread.join(5)
        listener.close()
    return seen


def _mtls_server(directory: Path, name: str) -> ssl.SSLContext:
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH, cafile=str(directory / "ca.pem"))
    context.verify_mode = ssl.CERT_REQUIRED
    context.load_cert_chain(str(directory / f"{name}.pem"), str(directory / f"{name}.key"))
    return context


def _client(cafile: Path, cert: Path, key: Path) -> ssl.SSLContext:
    context = ssl.create_default_context(cafile=str(cafile))
    context.load_cert_chain(str(cert), str(key))
    return context


def test_mutual_tls_between_two_identities_of_one_authority(tmp_path: Path):
    make_certs(tmp_path, parse_hosts(["router", "planner"], []))
    client = _client(tmp_path / "ca.pem", tmp_path / "planner.pem", tmp_path / "planner.key")
    seen = _handshake(_mtls_server(tmp_path, "router"), client, "localhost")
    assert seen.get("reply") == b"ok", seen
    assert dict(entry[0] for entry in seen["peer"]["subject"])["commonName"] == "planner"
    # The router's certificate names 127.0.0.1 too: a client dialling the address checks it.
    assert _handshake(_mtls_server(tmp_path, "router"), client, "127.0.0.1").get("reply") == b"ok"


def test_a_client_certificate_of_another_authority_is_refused(tmp_path: Path):
    make_certs(tmp_path, parse_hosts(["router"], []))
    foreign = trustme.CA()
    impostor = foreign.issue_cert("planner")
    impostor.cert_chain_pems[0].write_to_path(str(tmp_path / "impostor.pem"))
    impostor.private_key_pem.write_to_path(str(tmp_path / "impostor.key"))
    client = _client(tmp_path / "ca.pem", tmp_path / "impostor.pem", tmp_path / "impostor.key")
    seen: dict = {}
    try:
        seen = _handshake(_mtls_server(tmp_path, "router"), client, "localhost")
    except (ssl.SSLError, OSError):
        pass  # with TLS 1.3 the client learns of the refusal when it reads, or not at all
    assert "reply" not in seen
    with pytest.raises(CertError, match="impostor.pem does not verify against ca.pem"):
        verify(tmp_path, "impostor")


def test_a_server_is_checked_against_the_names_it_was_made_for(tmp_path: Path):
    make_certs(tmp_path, parse_hosts(["router"], ["router=10.0.0.1"]))
    server = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    server.load_cert_chain(str(tmp_path / "router.pem"), str(tmp_path / "router.key"))
    client = ssl.create_default_context(cafile=str(tmp_path / "ca.pem"))
    with pytest.raises(ssl.SSLCertVerificationError, match="match|mismatch"):
        _handshake(server, client, "planner.lan")


def test_the_host_certificate_is_kept_remade_for_a_new_name_or_a_foreign_signer(tmp_path: Path):
    host = HostCert("tablet", dns=["localhost"], ips=["127.0.0.1"])
    assert ensure_host_certificate(tmp_path, host, renew_before=0) is True
    authority = (tmp_path / "ca.pem").read_bytes()
    first = (tmp_path / "tablet.pem").read_bytes()
    assert ensure_host_certificate(tmp_path, host, renew_before=0) is False
    assert (tmp_path / "tablet.pem").read_bytes() == first

    wider = HostCert("tablet", dns=["localhost", "tablet.lan"], ips=["127.0.0.1", "10.0.0.7"])
    assert ensure_host_certificate(tmp_path, wider, renew_before=0) is True
    assert info(tmp_path / "tablet.pem").names == {"localhost", "tablet.lan", "127.0.0.1", "10.0.0.7"}

    # Expiring within the renewal margin: remade.
    assert ensure_host_certificate(tmp_path, wider, renew_before=10_000 * 86400.0) is True

    # Replaced by a certificate of another authority (same names): remade under ours.
    foreign = trustme.CA().issue_cert("localhost", "tablet.lan", "127.0.0.1", "10.0.0.7")
    foreign.cert_chain_pems[0].write_to_path(str(tmp_path / "tablet.pem"))
    assert ensure_host_certificate(tmp_path, wider, renew_before=0) is True
    verify(tmp_path, "tablet")
    assert (tmp_path / "ca.pem").read_bytes() == authority  # a tablet trusting it keeps trusting the server


def test_describe_and_unreadable_files_name_the_file(tmp_path: Path):
    make_certs(tmp_path, parse_hosts(["sim"], ["sim=10.1.2.3"]))
    text = describe(tmp_path, "sim")
    assert text.startswith("CN=sim; DNS:sim, DNS:localhost, IP:127.0.0.1, IP:10.1.2.3; valid until ")
    (tmp_path / "planner.pem").write_text("not a certificate")
    with pytest.raises(CertError, match=r"planner\.pem: not a readable PEM certificate"):
        verify(tmp_path, "planner")
    (tmp_path / "ca.key").write_text("garbage")
    with pytest.raises(CertError, match=r"ca\.key: not a readable unencrypted PEM private key"):
        make_certs(tmp_path, parse_hosts(["ar"], []))
