"""Services meet only over Zenoh: no service imports another service's package.

Every module under ``services/`` is parsed (``ast``, nothing is imported) and each import it makes,
absolute or relative, at module level or inside a function, is resolved to a module name. What is
allowed (docs/architecture.md, "Packages and who owns which contract"):

- a module of ``services/<X>/`` imports ``protocol``, ``runtime``, third-party and standard modules, and its own
  package ``services.<X>``; never ``services.<Y>`` (Y ≠ X) nor a top-level ``services`` module,
  except that ``services/<X>/__main__.py`` may import the ``services.cli`` dispatcher (so that
  ``python -m services.<X>`` is ``arroch <X>``);
- the top-level modules (``services/cli.py``, ``services/demo.py``) import no service package;
  the dispatcher loads each sub-command by name from ``COMMANDS``, whose entries must be
  ``protocol`` or ``runtime`` modules, top-level ``services`` modules or a service's ``cli`` module.

What two services share lives in ``protocol/`` (the wire) and ``runtime/`` (the code they run alike).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from services.cli import COMMANDS

ROOT = Path(__file__).resolve().parents[1]
SERVICES = ROOT / "services"
DISPATCHER = "services.cli"


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _service_of(module: str) -> str | None:
    """The service package a ``services.*`` module belongs to (None: top level, or not under services)."""
    parts = module.split(".")
    if parts[0] != "services" or len(parts) < 2 or not (SERVICES / parts[1]).is_dir():
        return None
    return parts[1]


def _imports(source: str, module: str, is_package: bool) -> list[tuple[int, str]]:
    """(line, imported module) for every import in ``source``, relative ones resolved."""
    package = module if is_package else module.rpartition(".")[0]
    found: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ""
            if prefix == "services":  # ``from services import sim`` imports the package services.sim
                found += [(node.lineno, f"services.{alias.name}") for alias in node.names]
            else:
                found.append((node.lineno, prefix))
    return found


def violations(source: str, module: str, *, is_package: bool = False, main: bool = False) -> list[str]:
    """What ``source`` (the text of ``module``) imports that it may not, one line per import."""
    own = _service_of(module)
    out = []
    for line, target in _imports(source, module, is_package):
        if target != "services" and not target.startswith("services."):
            continue
        other = _service_of(target)
        if own is not None and other == own:
            continue
        if own is not None and main and target == DISPATCHER:
            continue
        if other is None and own is None:
            continue  # top level importing top level (e.g. the dispatcher's own helpers)
        out.append(f"{module}:{line} imports {target}")
    return sorted(set(out))


def _service_modules() -> list[Path]:
    return sorted(p for p in SERVICES.rglob("*.py") if "__pycache__" not in p.parts)


def test_no_service_imports_another_services_package():
    problems = []
    for path in _service_modules():
        problems += violations(
            path.read_text(encoding="utf-8"),
            _module_name(path),
            is_package=path.name == "__init__.py",
            main=path.name == "__main__.py",
        )
    assert problems == [], "services meet only over Zenoh; share through protocol/:\n" + "\n".join(problems)


def test_the_dispatcher_loads_only_command_modules():
    for name in COMMANDS:
        service = _service_of(name)
        allowed = name.startswith(("protocol.", "runtime.")) or (
            name.startswith("services.") and (service is None or name.endswith(".cli"))
        )
        assert allowed, f"COMMANDS entry {name}: expected a protocol or runtime module or a service's cli module"


@pytest.mark.parametrize(
    "source, module, expected",
    [
        ("from services.restrictor.vocabulary import check_program", "services.planner.constraints", 1),
        ("import services.supervisor.catalog as catalog", "services.experiments.trial", 1),
        ("def f():\n    from services.sim.human import HumanConfig", "services.experiments.cli", 1),
        ("from ...sim import human", "services.ar_client.web.server", 1),  # relative, climbing out of ar_client
        ("from services import sim", "services.ros2.bridge", 1),
        ("from services.cli import main", "services.planner.service", 1),  # only __main__ may
        ("from services.demo import run", "services.planner.service", 1),
        ("from ..world import WorldView", "services.ar_client.web.bridge", 0),  # its own package
        ("from services.planner.motion import plan", "services.planner.service", 0),
        ("from runtime.feedback_client import send_feedback", "services.sim.feedback", 0),
        ("import numpy as np", "services.sim.world", 0),
    ],
)
def test_the_check_catches_what_it_should(source: str, module: str, expected: int):
    assert len(violations(source, module)) == expected, violations(source, module)
