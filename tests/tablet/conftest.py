"""Fixtures for the tablet tests: a headless Chromium (skipped when the machine has none)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from tests.tablet.browser import Browser, chromium_path


@pytest.fixture
def browser() -> Iterator[Callable[..., Browser]]:
    """``browser(fake_camera=PATH, window=(w, h))`` starts Chromium; every one is closed at teardown."""
    if chromium_path() is None:
        pytest.skip(
            "tablet page in a browser: no Chromium on this machine "
            "(`make test` installs it when run as root; else: sudo apt-get install chromium)"
        )
    opened: list[Browser] = []

    def _open(**kwargs) -> Browser:  # noqa: ANN003
        b = Browser(**kwargs)
        opened.append(b)
        return b

    yield _open
    for b in opened:
        b.close()
