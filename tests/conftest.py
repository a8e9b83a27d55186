"""Fixtures shared by the tests that talk over a real Zenoh router."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from fleet.bus import open_router
from fleet.supervisor.launcher import free_port


@pytest.fixture(scope="module")
def router_endpoint() -> Iterator[str]:
    """A Zenoh router on a free loopback port (multicast scouting off, as every fleet session),
    shared by one test module; its tests keep apart by fleet names of their own."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_router([endpoint])
    try:
        yield endpoint
    finally:
        router.close()


FLEETS = "fleets"


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run as the README runs the suite (``-n 2``, with ``--dist loadgroup`` from pyproject):
    the multi-process tests are one group, so one worker runs them one after another, those
    marked slow first, and never two fleets at once (a fleet at ``--speed 0`` takes both cores,
    and two starve each other into runs no user would see); every other test module is a group
    of its own (its module fixtures are made once), taken by whichever worker is free, so the
    other worker runs nearly all of them while the fleets run."""
    for item in items:
        integration = item.get_closest_marker("integration") is not None
        group = FLEETS if integration else item.nodeid.split("::", 1)[0]
        item.add_marker(pytest.mark.xdist_group(group))
    items.sort(
        key=lambda item: (
            item.get_closest_marker("integration") is None,
            item.get_closest_marker("slow") is None,
        )
    )
