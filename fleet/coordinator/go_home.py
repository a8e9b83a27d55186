"""When each robot at work goes to charge, and where: the go-home points of the robots at work
counted together (``planners.battery.go_home_points``) on the docks as the coordinator's
``Docking`` (:mod:`fleet.coordinator.charging`) sees them: the robots bound for each dock, the
docks a body blocks."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

from fleet.coordinator.job import Job
from planners.battery import BatterySpec, GoHome, go_home_points

Pose = tuple[float, float, float]


class Docking(Protocol):
    """What the go-home rule reads of the docks (``fleet.coordinator.charging.Docking``)."""

    job: Job
    spec: BatterySpec
    docks: Sequence[Pose]

    def usable(self, k: int) -> bool: ...

    def trip_to(self, k: int, xy: tuple[float, float]) -> float: ...

    def ahead(self, k: int) -> list[float]: ...


def at_work(job: Job) -> list[str]:
    """The robots the go-home rule counts: in the market, not on a trip, placed, with a battery
    heard."""
    return [
        rid
        for rid, r in sorted(job.robots.items())
        if r.in_market and not r.docking and r.xy is not None and r.charge >= 0
    ]


def trips_s(docking: Docking, xy: tuple[float, float]) -> tuple[float, ...]:
    """Travel time from ``xy`` to each dock, inf to a dock no robot can drive onto."""
    return tuple(
        docking.trip_to(k, xy) if docking.usable(k) else math.inf for k in range(len(docking.docks))
    )


def points(docking: Docking) -> dict[str, tuple[int | None, float]]:
    """Per robot at work, in the order they fall due, the dock it would charge at on falling
    due and its go-home point, counting the robots bound for each dock and the robots at work
    that fall due before it and will still be there."""
    robots = docking.job.robots
    rids = at_work(docking.job)
    users = [GoHome(robots[rid].charge, trips_s(docking, _xy(docking, rid))) for rid in rids]
    ahead = [docking.ahead(k) for k in range(len(docking.docks))]
    return {rids[i]: (k, p) for i, k, p in go_home_points(docking.spec, users, ahead)}


def alone(docking: Docking, rid: str) -> tuple[int | None, float]:
    """The dock ``rid`` would charge at and its go-home point with the docks as they stand (the
    robots bound for each counted, no robot at work)."""
    r = docking.job.robots[rid]
    if r.xy is None:
        return None, 0.0
    ahead = [docking.ahead(k) for k in range(len(docking.docks))]
    ((_, k, p),) = go_home_points(docking.spec, [GoHome(r.charge, trips_s(docking, r.xy))], ahead)
    return k, p


def _xy(docking: Docking, rid: str) -> tuple[float, float]:
    xy = docking.job.robots[rid].xy
    assert xy is not None
    return xy
