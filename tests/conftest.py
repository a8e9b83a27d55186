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
