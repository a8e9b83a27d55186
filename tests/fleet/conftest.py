"""Fixtures of the coordinator's tests on a real router."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from fleet.bus import Bus
from fleet.supervisor.launcher import free_port


@pytest.fixture
def buses(router_endpoint: str) -> Iterator[tuple[Bus, Bus, Bus]]:
    """The coordinator's, the simulator's and robot-0's agent's buses, on a fleet of their own."""
    fleet = f"t{free_port()}"
    with (
        Bus("coordinator", "coordinator", connect=[router_endpoint], fleet=fleet) as coord,
        Bus("sim", "sim", connect=[router_endpoint], fleet=fleet) as sim,
        Bus("agent", "robot-0", connect=[router_endpoint], fleet=fleet) as agent,
    ):
        yield coord, sim, agent
