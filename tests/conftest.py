"""Fixtures shared by the tests that talk over a real Zenoh router."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from fleet.bus import open_router
from fleet.supervisor.launcher import free_port

# one fleet at a time in the whole run, on any number of workers (tests/fleet_lock.py)
pytest_plugins = ["fleet_lock"]


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
    """Order and group the tests for ``-n 2`` (the README's run, ``--dist loadgroup`` from
    pyproject). The multi-process tests (marked ``integration``) come first, those marked slow
    first of all, so the longest fleets start at once; and they are one xdist group, so one
    worker runs them one after another while the other runs nearly all the rest (every other
    module is a group of its own, its module fixtures made once, taken by whichever worker is
    free). That grouping rests on xdist rewriting each node id it schedules by (``…@fleets``),
    which pytest-xdist 3.8 does under pytest 9.0 but silently does not under the structured
    node ids of pytest's main branch (pytest-xdist#1386); then the fleets go round both
    workers. Either way two fleets never run at once (a fleet at ``--speed 0`` takes both
    cores, and two would starve each other into runs no user would see): every
    ``integration`` test holds the lock of ``tests/fleet_lock.py``, shared by the workers, so
    at worst one worker waits for the other's fleet."""
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
