"""Fixtures of the study tests: the tablet tests' headless Chromium (skipped where there is none)."""

from tests.tablet.conftest import browser  # noqa: F401 - a fixture, used by name
