"""Fixtures for the AR client tests."""

from __future__ import annotations

import pytest

from services.ar_client.detect import apriltag_detector


@pytest.fixture(scope="session")
def pupil():
    """The process's one pupil-apriltags detector (several instances corrupt the heap at teardown)."""
    return apriltag_detector()
