"""Which code produced a trial: a fingerprint of the sources the services run.

Every trial starts fresh processes, so a service's source edited while a sweep runs changes the
trials that start afterwards. The fingerprint (SHA-256 over the relative path and content of every
``.py``, ``.lp`` and ``.toml`` file of ``protocol/``, ``runtime/`` and ``services/``, this package
excepted: it runs trials but decides none of their numbers; ``runtime/`` holds the robots' executor,
the controller and the site generator the services run) is taken at the start of each trial and written to
``timing.csv``; the report says when a sweep's trials come from more than one version of the code.

The versions of Python and of every installed dependency arroch declares (:func:`dependency_versions`)
go into each session's entry of the sweep's runs file: a figure can move with a library as well as
with the code.
"""

from __future__ import annotations

import hashlib
import platform
import re
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCES = ("protocol", "runtime", "services")
SUFFIXES = (".py", ".lp", ".toml")
EXCLUDED = Path(__file__).resolve().parent  # services/experiments


def code_fingerprint(root: Path = ROOT) -> str:
    """12 hex digits identifying the services' sources as they are on disk now."""
    digest = hashlib.sha256()
    for top in SOURCES:
        for path in sorted((root / top).rglob("*")):
            if path.suffix not in SUFFIXES or not path.is_file() or EXCLUDED in path.resolve().parents:
                continue
            digest.update(str(path.relative_to(root)).encode("utf-8") + b"\0")
            digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()[:12]


def dependency_versions(distribution: str = "arroch") -> dict[str, str]:
    """``{name: version}`` of Python and of each installed requirement of ``distribution`` (extras included).

    A requirement that is not installed (an extra not asked for) is left out; an uninstalled
    ``distribution`` (a source tree run in place) gives Python's version alone.
    """
    versions = {"python": platform.python_version()}
    try:
        requirements = metadata.requires(distribution) or []
    except metadata.PackageNotFoundError:
        return versions
    for requirement in requirements:
        name = re.match(r"[A-Za-z0-9._-]+", requirement).group(0)
        if name.lower() == distribution.lower() or name in versions:
            continue  # the distribution's own extras (arroch[apriltag]) name no new package
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return versions
