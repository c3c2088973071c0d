"""Loading a site: read the file, parse TOML, check the format, build and validate the model."""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

from .build import build_site
from .errors import SiteError
from .fileformat import check_document
from .model import Site

PACKAGED_SOURCE = "<packaged office>"


def default_site_path() -> Path:
    """The packaged ``office`` site file (protocol/sites/office.toml)."""
    return Path(str(resources.files("protocol.sites").joinpath("office.toml")))


def read_text(path: str | Path | None) -> tuple[str, str, str]:
    """``(text, file name for messages, source)`` of a site file; ``None`` is the packaged office."""
    if path is None:
        resource = resources.files("protocol.sites").joinpath("office.toml")
        return resource.read_text(encoding="utf-8"), "office.toml", PACKAGED_SOURCE
    p = Path(path)
    try:
        return p.read_text(encoding="utf-8"), p.name, str(p)
    except FileNotFoundError:
        raise SiteError(p.name, "", f"no such site file: {p}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SiteError(p.name, "", f"cannot read {p}: {exc}") from None


def parse_toml(text: str, file: str) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SiteError(file, "", f"not valid TOML: {exc}") from None


def load_site(path: str | Path | None = None) -> Site:
    """Load and validate a site file (``None``: the packaged ``office`` site).

    Raises :class:`SiteError` (a ``ValueError``) naming the file and the offending entry.
    """
    text, file, source = read_text(path)
    return build_site(check_document(file, parse_toml(text, file)), file, source)


def loads_site(text: str, file: str = "<string>") -> Site:
    """Load and validate a site from TOML text (e.g. from :func:`runtime.site.generate.generate_site`)."""
    return build_site(check_document(file, parse_toml(text, file)), file, file)
