"""The service graph's declaration (protocol/graph.py) holds together, agrees with the access-control
table and the recorder's key list, and the files generated from it (docs/graph.md, docs/graph.png)
are up to date. tests/integration/test_graph_declared.py checks it against running services."""

from __future__ import annotations

import inspect
import json
import subprocess
import sys
from pathlib import Path

import zenoh

from protocol.graph import BY_NAME, FRAMEWORK, RECORDED, SERVICES
from protocol.keys import Keys
from protocol.messages import ALL_MESSAGES
from runtime.launch.catalog import RECORDER as RECORDER_SPEC
from runtime.launch.catalog import SERVICES as LAUNCHED
from services.graph.draw import draw
from services.graph.formats import GENERATED_BY, to_dot, to_json, to_markdown, to_text
from services.recorder.topics import recorded_keys
from services.supervisor.deployment.acl import GUARDS, ROLES

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "graph.md"
PICTURE = ROOT / "docs" / "graph.png"


def _builder_keys() -> set[str]:
    """Every key a :class:`Keys` builder makes with its defaults (wildcards), below the namespace."""
    keys = Keys("namespace")
    built = set()
    for name, method in inspect.getmembers(keys, inspect.ismethod):
        parameters = inspect.signature(method).parameters.values()
        if name.startswith("_") or any(p.default is inspect.Parameter.empty for p in parameters):
            continue
        built.add(method().removeprefix(keys.prefix + "/"))
    return built


def _overlap(a: str, b: str) -> bool:
    return zenoh.KeyExpr(a).intersects(zenoh.KeyExpr(b))


def test_every_arroch_key_comes_from_a_keys_builder_and_every_type_from_messages() -> None:
    built = _builder_keys()
    for service in SERVICES:
        for e in service.endpoints:
            where = f"{service.name} {e.direction} {e.key}"
            assert e.is_ros2 or e.key in built, f"{where}: not a protocol.keys.Keys key ({sorted(built)})"
            assert isinstance(e.payload, str) or e.payload in ALL_MESSAGES, f"{where}: {e.payload} is no message"
            assert e.purpose, f"{where}: no purpose"


def test_names_are_unique_and_keys_unique_per_direction() -> None:
    assert len(BY_NAME) == len(SERVICES)
    for service in SERVICES:
        seen = [(e.direction, e.key) for e in service.endpoints]
        assert len(seen) == len(set(seen)), f"{service.name} lists a key twice in one direction"


def test_what_the_graph_publishes_and_serves_the_access_control_allows() -> None:
    """Who *may* publish (services/supervisor/deployment/acl.py) covers who *does* (the graph)."""
    for service in SERVICES:
        if not service.role:
            continue  # a diagnostic or offline tool, not part of a secure deployment
        assert service.role in ROLES, f"{service.name}: role {service.role!r} is not an access-control role"
        for e in service.endpoints:
            if e.is_ros2:
                continue
            for guard in GUARDS:
                if not _overlap(guard.key, e.key):
                    continue
                where = f"{service.name} (role {service.role}) {e.direction} {e.key}: guard {guard.key}"
                if e.direction == "pub":
                    assert service.role in guard.publishers, f"{where} lets only {guard.publishers} publish"
                elif e.direction == "serve":
                    assert service.role in guard.servers, f"{where} lets only {guard.servers} serve"
                elif e.direction == "query" and guard.queriers is not None:
                    assert service.role in guard.queriers, f"{where} lets only {guard.queriers} ask"


def test_services_run_as_the_role_arroch_up_gives_them() -> None:
    """``arroch up`` renders each service's Zenoh config for its identity (runtime/launch/catalog.py)."""
    for spec in (*LAUNCHED.values(), RECORDER_SPEC):
        expected = spec.identity if spec.identity in ROLES else ""  # ping: no access-control role
        assert BY_NAME[spec.name].role == expected, f"{spec.name}: arroch up runs it as {spec.identity!r}"


def test_every_message_a_service_publishes_is_recorded() -> None:
    """A run's recording misses no stream: each ARROCH message a service publishes is on a key the
    recorder hears, with its type (ping's replies aside: a measurement's own round trips)."""
    recorded = set(RECORDED)
    missing = [
        (service.name, e.key, e.payload.__name__)
        for service in SERVICES
        if service.name != "ping"
        for e in service.endpoints
        if e.direction == "pub" and not isinstance(e.payload, str) and (e.key, e.payload) not in recorded
    ]
    assert not missing, f"published but never recorded: {missing}"
    assert all(key.startswith("arroch/namespace/") for key, _ in recorded_keys(Keys("namespace")))


def test_every_format_names_every_service_and_key() -> None:
    body = json.loads(to_json(SERVICES))
    assert [s["name"] for s in body["services"]] == list(BY_NAME)
    assert len(body["framework"]) == len(FRAMEWORK)
    text, dot = to_text(SERVICES), to_dot(SERVICES)
    for service in SERVICES:
        assert f"\n{service.name}  (" in text
        assert f'"service:{service.name}"' in dot
        for e in service.endpoints:
            assert f'"key:{e.key}"' in dot


def test_docs_graph_md_is_up_to_date() -> None:
    assert DOC.read_text(encoding="utf-8") == to_markdown(SERVICES), f"docs/graph.md is stale: run `{GENERATED_BY}`"


def test_the_picture_is_drawn(tmp_path: Path) -> None:
    assert PICTURE.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", "docs/graph.png: run `arroch graph --out docs/graph.png`"
    out = tmp_path / "graph.svg"
    draw(SERVICES, out)
    svg = out.read_text(encoding="utf-8")
    assert svg.lstrip().startswith("<?xml") and "robot/*/pose" in svg


def test_arroch_graph_command(tmp_path: Path) -> None:
    run = [sys.executable, "-m", "services.cli", "graph"]
    planner = subprocess.run([*run, "--service", "planner"], capture_output=True, text=True, cwd=ROOT, check=True)
    assert "planner  (arroch planner; role planner)" in planner.stdout and "\nsim  (" not in planner.stdout
    out = tmp_path / "graph.json"
    subprocess.run([*run, "--format", "json", "--out", str(out)], capture_output=True, cwd=ROOT, check=True)
    assert json.loads(out.read_text())["services"][0]["name"] == SERVICES[0].name
    wrong = subprocess.run([*run, "--service", "nobody"], capture_output=True, text=True, cwd=ROOT)
    assert wrong.returncode == 2 and "no service nobody" in wrong.stderr
