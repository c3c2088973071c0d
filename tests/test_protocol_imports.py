"""``protocol`` is the typed wire and nothing else: it imports only the standard library, msgspec,
numpy and itself; ``runtime`` (the code processes run alike) imports no service.

Two checks: every import statement under ``protocol/`` parsed with ``ast`` (nothing is imported),
and every module of ``protocol`` imported in a fresh interpreter whose ``sys.modules`` is compared
with what it held before. A third-party import in ``protocol`` belongs in ``runtime/``.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "protocol"
RUNTIME = ROOT / "runtime"
ALLOWED = frozenset({"msgspec", "numpy", "protocol"})
# Loaded before protocol in the probe: what these pull in is theirs (msgspec loads typing_extensions,
# when installed, the first time it reads a Struct's annotations).
ALLOWED_PRELOAD = ("msgspec", "msgspec.msgpack", "msgspec.json", "msgspec.structs", "msgspec._utils", "numpy")
# Imports inside a function, never run by importing protocol: (module, top-level name) -> why.
DEFERRED = {
    ("protocol.site.grid", "cv2"): "Site.occupancy_grid inflates obstacles with OpenCV's distance transform",
}


def _modules(package: Path) -> list[tuple[str, Path]]:
    found = []
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        found.append((".".join(parts), path))
    return found


def _imports(path: Path, module: str) -> list[tuple[int, str, bool]]:
    """(line, imported module, at module level) for every import in ``path``, relative ones resolved."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    top_level = {id(node) for node in tree.body}
    for node in tree.body:  # imports under `if TYPE_CHECKING:` / `try:` at module level run on import too
        if isinstance(node, (ast.If, ast.Try)):
            top_level |= {id(child) for child in ast.walk(node)}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name, id(node) in top_level) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.append((node.lineno, target, id(node) in top_level))
    return found


def _allowed(top: str) -> bool:
    return top in ALLOWED or top in sys.stdlib_module_names or top == "__future__"


def test_protocol_imports_only_the_standard_library_msgspec_numpy_and_itself():
    problems = []
    used_deferred = set()
    for module, path in _modules(PROTOCOL):
        for line, target, _ in _imports(path, module):
            top = target.split(".")[0]
            if _allowed(top):
                continue
            if (module, top) in DEFERRED:
                used_deferred.add((module, top))
                continue
            problems.append(f"{path.relative_to(ROOT)}:{line} imports {target}")
    assert problems == [], "protocol/ is the typed wire; move what needs these to runtime/:\n" + "\n".join(problems)
    assert used_deferred == set(DEFERRED), f"stale DEFERRED entries: {set(DEFERRED) - used_deferred}"


def test_deferred_imports_stay_inside_functions():
    for (module, top), _why in DEFERRED.items():
        path = PROTOCOL.joinpath(*module.split(".")[1:]).with_suffix(".py")
        at_module_level = [
            line for line, target, top_level in _imports(path, module) if target.split(".")[0] == top and top_level
        ]
        assert at_module_level == [], f"{module} imports {top} at module level (lines {at_module_level})"


def test_importing_every_protocol_module_loads_nothing_else():
    modules = [name for name, _ in _modules(PROTOCOL)]
    probe = (
        "import importlib, json, sys\n"
        f"sys.path.insert(0, {str(ROOT)!r})\n"
        f"for name in {ALLOWED_PRELOAD!r}:\n"
        "    importlib.import_module(name)\n"
        "before = set(sys.modules)\n"
        "loaded = {}\n"
        f"for name in {modules!r}:\n"
        "    seen = set(sys.modules)\n"
        "    importlib.import_module(name)\n"
        "    loaded[name] = sorted({m.split('.')[0] for m in set(sys.modules) - seen})\n"
        "print(json.dumps({'before': sorted(before), 'loaded': loaded}))\n"
    )
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.strip().splitlines()[-1])
    problems = {
        name: others
        for name, tops in report["loaded"].items()
        if (others := [top for top in tops if not _allowed(top)])
    }
    assert problems == {}, f"importing these protocol modules loaded third-party modules: {problems}"
    assert set(report["loaded"]) == set(modules)


def test_runtime_imports_no_service():
    problems = [
        f"{path.relative_to(ROOT)}:{line} imports {target}"
        for module, path in _modules(RUNTIME)
        for line, target, _ in _imports(path, module)
        if target == "services" or target.startswith("services.")
    ]
    assert problems == [], "runtime/ sits below the services:\n" + "\n".join(problems)
