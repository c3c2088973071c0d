"""Fixtures and markers of the reliability tests (the shared ones are in tests/conftest.py)."""

from __future__ import annotations

import pytest


def pytest_configure(config: pytest.Config) -> None:
    # Also registered by tests/deploy/conftest.py; repeated here so this folder runs on its own.
    config.addinivalue_line(
        "markers",
        "netns: builds Linux network namespaces (root, iproute2); ARROCH_SKIP_NETNS=1 or -m 'not netns' deselects",
    )
