"""Sites and planners shared by the planner tests (planning the same site twice is a waste of time)."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import pytest

from protocol.site import Site, load_site, loads_site
from runtime.site.generate import generate_site
from services.planner.planner import PlannerSettings, TaskPlanner

SITES = Path(__file__).resolve().parent / "sites"


@cache
def site_named(name: str) -> Site:
    """``office`` (packaged), ``gen<N>`` (generated, N robots, seed 0) or a file in tests/planner/sites."""
    if name == "office":
        return load_site()
    if name.startswith("gen"):
        return loads_site(generate_site(int(name[3:]), 3, seed=0))
    return load_site(SITES / f"{name}.toml")


@cache
def planner_for(name: str) -> TaskPlanner:
    return TaskPlanner(site_named(name), PlannerSettings(time_limit=60.0, joint_time_limit=60.0))


@pytest.fixture(scope="session")
def office() -> Site:
    return site_named("office")
