"""Fixtures of the restrictor tests: the small ``lab`` site next to this file and the packaged library."""

from __future__ import annotations

from pathlib import Path

import pytest

from protocol.site import load_site
from services.restrictor.library import Library, load_library

HERE = Path(__file__).resolve().parent
LAB = HERE / "lab.toml"  # rooms corridor, storage, room_a, lab; d_storage (human-operated), d_lab (automatic)


@pytest.fixture(scope="session")
def lab_site():
    return load_site(LAB)


@pytest.fixture(scope="session")
def library() -> Library:
    return load_library()
