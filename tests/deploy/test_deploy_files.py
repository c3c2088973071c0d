"""The deployment files: certificates, rendered Zenoh configs, the access-control table, systemd units."""

from __future__ import annotations

import argparse
import re
import shlex
import shutil
import ssl
import stat
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh
from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from runtime.certs import CertError, make_certs, parse_hosts
from runtime.launch.catalog import DEFAULT_SERVICES
from services.cli import build_parser
from services.supervisor.deployment import acl
from services.supervisor.deployment.render import RenderError, Request, render
from tests.procs import ROOT, arroch

# Zenoh closes a link after a blocked send waits this long (µs); its 5 s default lost a stalled subscriber's messages
WAIT_BEFORE_CLOSE = "transport/link/tx/queue/congestion_control/block/wait_before_close"

DEPLOY = ROOT / "deploy"
UNITS = ["router", *DEFAULT_SERVICES, "tablet"]
ZENOH_IDENTITY = {"tablet": "ar"}  # the page joins Zenoh with the AR client's certificate and rights


def test_certs_name_the_role_list_the_addresses_and_reuse_the_authority(tmp_path: Path):
    make_certs(tmp_path, parse_hosts(["router", "planner"], ["router=10.0.0.1,router.lan"]))
    router = x509.load_pem_x509_certificate((tmp_path / "router.pem").read_bytes())
    assert router.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == "router"
    alt = router.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert set(alt.get_values_for_type(x509.DNSName)) == {"router", "router.lan", "localhost"}
    assert {str(ip) for ip in alt.get_values_for_type(x509.IPAddress)} == {"10.0.0.1", "127.0.0.1"}
    usages = router.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
    assert set(usages) == {ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH}
    assert router.extensions.get_extension_for_class(x509.BasicConstraints).value.ca is False
    for key in ("ca.key", "router.key", "planner.key"):
        assert stat.S_IMODE((tmp_path / key).stat().st_mode) == 0o600
    ca_before = (tmp_path / "ca.pem").read_bytes()
    summary = make_certs(tmp_path, parse_hosts(["router", "ar"], []))  # a host added later
    assert (tmp_path / "ca.pem").read_bytes() == ca_before and "kept the existing authority" in summary[0]
    assert any("router.pem: kept" in line for line in summary)
    # The later host chains to the same authority (checked by the ssl module, not by our code).
    trusting = ssl.create_default_context(cafile=str(tmp_path / "ca.pem"))
    assert any("ARROCH deployment CA" in str(c["subject"]) for c in trusting.get_ca_certs())
    ar = x509.load_pem_x509_certificate((tmp_path / "ar.pem").read_bytes())
    ar.verify_directly_issued_by(x509.load_pem_x509_certificate(ca_before))


@pytest.mark.parametrize(
    "hosts, sans, message",
    [
        (["router"], ["planner=10.0.0.2"], "'planner' is not one of the --hosts"),
        (["router"], ["router=not an address!"], "neither an IP address nor a DNS name"),
        (["ca"], [], "reserved"),
        (["bad/name"], [], "use letters, digits"),
    ],
)
def test_bad_certificate_requests_are_refused_clearly(hosts, sans, message):
    with pytest.raises(CertError, match=re.escape(message)):
        parse_hosts(hosts, sans)


def test_deploy_cli_makes_certs_and_renders_every_role_into_configs_zenoh_accepts(tmp_path: Path):
    certs, out = tmp_path / "certs", tmp_path / "zenoh"
    hosts = ",".join([*acl.ROLES, *acl.INFRASTRUCTURE])
    made = subprocess.run(
        arroch("deploy", "certs", "--out", str(certs), "--hosts", hosts, "--san", "router=10.0.0.1"),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert made.returncode == 0, made.stderr
    rendered = subprocess.run(
        arroch(
            "deploy",
            "render",
            "--profile",
            "secure",
            "--role",
            "all",
            "--certs",
            str(certs),
            "--router",
            "10.0.0.1:7447",
            "--out-dir",
            str(out),
        ),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert rendered.returncode == 0, rendered.stderr
    for role in [*acl.ROLES, *acl.INFRASTRUCTURE]:
        config = zenoh.Config.from_file(str(out / f"{role}.json5"))
        mode = "router" if role == "router" else "client"
        assert config.get_json("mode") == f'"{mode}"'
        assert config.get_json(WAIT_BEFORE_CLOSE) == "60000000"  # Zenoh's 5 s closed busy subscribers' sessions
        if role != "router":
            assert config.get_json("connect/endpoints") == '["tls/10.0.0.1:7447"]'  # tls/ added to a bare address
            assert config.get_json("transport/link/tls/connect_certificate") == f'"{certs.resolve() / role}.pem"'


def test_plain_profile_renders_router_peer_and_client():
    router = zenoh.Config.from_json5(render(Request("plain", "router")))
    assert router.get_json("listen/endpoints") == '["tcp/0.0.0.0:7447"]'
    peer = zenoh.Config.from_json5(
        render(Request("plain", "sim", kind="peer", connect=["10.0.0.1:7447"], listen=["tcp/0.0.0.0:7448"]))
    )
    assert peer.get_json("mode") == '"peer"' and peer.get_json("listen/endpoints") == '["tcp/0.0.0.0:7448"]'
    client = zenoh.Config.from_json5(render(Request("plain", "ar", connect=["tcp/10.0.0.1:7447"])))
    assert client.get_json("scouting/multicast/enabled") == "false"
    assert {c.get_json(WAIT_BEFORE_CLOSE) for c in (router, peer, client)} == {"60000000"}


@pytest.mark.parametrize(
    "request_, message",
    [
        (Request("secure", "planner", certs=Path("/nonexistent"), connect=["tcp/10.0.0.1:7447"]), "speaks TLS only"),
        (
            Request("secure", "planner", certs=Path("/nonexistent"), connect=["10.0.0.1:7447"]),
            "missing /nonexistent/ca.pem",
        ),
        (Request("secure", "planner", connect=["10.0.0.1:7447"]), "needs --certs"),
        (Request("plain", "planner"), "needs --router"),
        (Request("plain", "planner", connect=["10.0.0.1"]), "has no port"),
        (Request("plain", "wizard", connect=["10.0.0.1:7447"]), "role 'wizard' is not one of"),
    ],
)
def test_render_refuses_what_would_not_work(request_, message):
    with pytest.raises(RenderError, match=re.escape(message)):
        render(request_)


def test_every_guard_names_known_roles_and_every_role_may_do_something():
    known = set(acl.ROLES)
    for guard in acl.GUARDS:
        for group in (guard.publishers, guard.servers, guard.readers or (), guard.queriers or ()):
            assert set(group) <= known, (guard.key, group)
    block = acl.access_control({"ar": ["ar-2"]})
    assert {"id": "ar", "cert_common_names": ["ar", "ar-2"]} in block["subjects"]
    rule_ids = {rule["id"] for rule in block["rules"]}
    assert all(set(policy["rules"]) <= rule_ids for policy in block["policies"])


def _env_file() -> dict[str, str]:
    values = {}
    for line in (DEPLOY / "arroch.env").read_text().splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            name, _, value = line.partition("=")
            values[name.strip()] = value.strip()
    return values


def _exec_start(unit: str) -> list[str]:
    """ExecStart as systemd expands it: ``${X}`` one word, ``$X`` split at spaces (none if empty)."""
    lines = (DEPLOY / "systemd" / f"arroch-{unit}.service").read_text().splitlines()
    line = next(text for text in lines if text.startswith("ExecStart="))
    env = _env_file()
    words: list[str] = []
    for word in shlex.split(line.removeprefix("ExecStart=")):
        if m := re.fullmatch(r"\$\{(\w+)\}", word):
            words.append(env[m.group(1)])
        elif m := re.fullmatch(r"\$(\w+)", word):
            words.extend(env[m.group(1)].split())
        else:
            words.append(word)
    return words


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def test_there_is_a_unit_for_every_service_and_the_tablet_page():
    assert sorted(p.name for p in (DEPLOY / "systemd").glob("*.service")) == sorted(
        f"arroch-{u}.service" for u in UNITS
    )


@pytest.mark.parametrize("unit", UNITS)
def test_each_unit_runs_its_service_with_its_rendered_config(unit: str):
    argv = _exec_start(unit)
    assert argv[0].startswith("/") and argv[1] == unit
    assert argv[argv.index("--zenoh-config") + 1] == f"/etc/arroch/zenoh/{ZENOH_IDENTITY.get(unit, unit)}.json5"
    commands = _subcommands()
    if unit not in commands:
        pytest.skip(f"`arroch {unit}` is not in this tree yet: its unit's options are checked once it is")
    commands[unit].parse_args(argv[2:])  # exits (fails the test) on an option the service does not have


def test_units_pass_systemd_analyze_verify(tmp_path: Path):
    if shutil.which("systemd-analyze") is None:
        pytest.skip("systemd-analyze is not installed")
    arroch_bin = Path(sys.executable).parent / "arroch"
    env = tmp_path / "arroch.env"
    shutil.copy(DEPLOY / "arroch.env", env)
    for unit in UNITS:
        text = (DEPLOY / "systemd" / f"arroch-{unit}.service").read_text()
        text = text.replace("/opt/arroch/.venv/bin/arroch", str(arroch_bin)).replace("/etc/arroch/arroch.env", str(env))
        (tmp_path / f"arroch-{unit}.service").write_text(text)
    result = subprocess.run(
        ["systemd-analyze", "verify", *(str(tmp_path / f"arroch-{u}.service") for u in UNITS)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    problems = [line for line in (result.stdout + result.stderr).splitlines() if "arroch-" in line]
    assert result.returncode == 0 and not problems, result.stdout + result.stderr


def test_deploy_acl_prints_a_block_zenoh_accepts():
    result = subprocess.run(arroch("deploy", "acl", "--cn", "ar=ar-2"), capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    config = zenoh.Config.from_json5("{access_control: " + result.stdout + "}")
    subjects = config.get_json("access_control/subjects")
    assert '"ar-2"' in subjects and config.get_json("access_control/default_permission") == '"deny"'
