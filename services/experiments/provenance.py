"""Which code produced a trial: a fingerprint of the sources the services run.

Every trial starts fresh processes, so a service's source edited while a sweep runs changes the
trials that start afterwards. The fingerprint (SHA-256 over the relative path and content of every
``.py``, ``.lp`` and ``.toml`` file of ``protocol/`` and ``services/``, this package excepted: it runs
trials but decides none of their numbers) is taken at the start of each trial and written to
``timing.csv``; the report says when a sweep's trials come from more than one version of the code.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCES = ("protocol", "services")
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
