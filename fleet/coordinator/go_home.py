"""When each robot at work goes to charge, and where: the go-home points of the robots at work
counted together (``planners.battery.go_home_points``) on the docks as the coordinator's
``Docking`` (:mod:`fleet.coordinator.charging`) sees them: the robots bound for each dock, the
docks a body blocks; and the order robots are sent home in at the job's end."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Protocol

from fleet.coordinator.job import Job
from planners.battery import BatterySpec, GoHome, go_home_points

Pose = tuple[float, float, float]


class DockView(Protocol):
    """What the go-home rule reads of the docks: the coordinator's
    (``fleet.coordinator.charging.Docking``)."""

    job: Job
    spec: BatterySpec
    docks: Sequence[Pose]

    def usable(self, k: int) -> bool: ...

    def trip_to(self, k: int, xy: tuple[float, float]) -> float: ...

    def ahead(self, k: int) -> list[float]: ...

    def free(self, k: int) -> bool: ...


def at_work(job: Job) -> list[str]:
    """The robots the go-home rule counts: in the market, not on a trip, placed, with a battery
    heard."""
    return [
        rid
        for rid, r in sorted(job.robots.items())
        if r.in_market and not r.docking and r.xy is not None and r.charge >= 0
    ]


def trips_s(docking: DockView, xy: tuple[float, float]) -> tuple[float, ...]:
    """Travel time from ``xy`` to each dock, inf to a dock no robot can drive onto."""
    return tuple(
        docking.trip_to(k, xy) if docking.usable(k) else math.inf for k in range(len(docking.docks))
    )


def points(docking: DockView) -> dict[str, tuple[int | None, float]]:
    """Per robot at work, in the order they fall due, the dock it would charge at on falling
    due and its go-home point, counting the robots bound for each dock and the robots at work
    that fall due before it and will still be there."""
    robots = docking.job.robots
    rids = at_work(docking.job)
    users = [GoHome(robots[rid].charge, trips_s(docking, _xy(docking, rid))) for rid in rids]
    ahead = [docking.ahead(k) for k in range(len(docking.docks))]
    return {rids[i]: (k, p) for i, k, p in go_home_points(docking.spec, users, ahead)}


def alone(docking: DockView, rid: str) -> tuple[int | None, float]:
    """The dock ``rid`` would charge at and its go-home point with the docks as they stand (the
    robots bound for each counted, no robot at work)."""
    r = docking.job.robots[rid]
    if r.xy is None:
        return None, 0.0
    ahead = [docking.ahead(k) for k in range(len(docking.docks))]
    ((_, k, p),) = go_home_points(docking.spec, [GoHome(r.charge, trips_s(docking, r.xy))], ahead)
    return k, p


def nearest_first(docking: DockView, rids: list[str]) -> list[str]:
    """``rids`` in the order to send them home so that each free dock goes to the robot nearest
    it (greedy matching over robot–dock pairs by travel time, the nearest pair first), then the
    robots left over (they wait) in the given order. Sent one by one in id order, the first
    robot would take the dock nearest it even when another robot stands by that dock, and the
    other would cross the floor to the far one."""
    free = [k for k in range(len(docking.docks)) if docking.free(k)]
    first = nearest_pairs_first(
        (docking.trip_to(k, xy), rid, k)
        for rid in rids
        for k in free
        if (xy := docking.job.robots[rid].xy) is not None
    )
    return first + [rid for rid in rids if rid not in first]


def nearest_pairs_first(pairs: Iterable[tuple[float, str, int]]) -> list[str]:
    """Greedy matching of robots to docks over ``pairs`` (travel time, robot, dock): the
    nearest pair first, then the nearest of the robots and docks left; the robots matched, in
    that order."""
    first: list[str] = []
    taken: set[int] = set()
    for _, rid, k in sorted(pairs):
        if rid not in first and k not in taken:
            first.append(rid)
            taken.add(k)
    return first


def _xy(docking: DockView, rid: str) -> tuple[float, float]:
    xy = docking.job.robots[rid].xy
    assert xy is not None
    return xy
