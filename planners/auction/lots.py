"""What one auction call sells: a single task, or a region of tasks.

The first allocation sells regions, one per robot, so each robot starts with a part of the floor
of its own, as a static split would give it (robots that interleave over the whole floor cross
each other's paths and drive over swept floor between tasks): either the tour's tasks cut into
runs of about equal time (:func:`regions`), or compact groups grown from each robot's start
(:func:`planners.auction.compact.compact_regions`, sold by :func:`region_lot` to that robot
alone). Everything sold later — a lost robot's remainder, tasks withdrawn to feed an idle robot
— goes task by task (:func:`task_lot`).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from planners.auction.compact import Region
from planners.auction.tasks import Task


@dataclass(frozen=True, eq=False)
class Lot:
    """One call's item: ``tasks`` in driving order from ``entry`` to ``exit``, each driven
    backwards where ``reverse`` says so (empty: all forwards). A lot bought backwards (entered
    at its exit) is driven last task first, each task the other way round (:meth:`driven`).
    ``gain_s``: what it is worth beyond its work, in seconds a bid takes off (a frontier's
    expected information; 0 for cleaning). ``robot``: the only robot that may win it (a compact
    region grown from its start), None for any."""

    id: str
    tasks: tuple[str, ...]
    entry: np.ndarray
    exit: np.ndarray
    time_s: float
    area_m2: float
    gain_s: float = 0.0
    reverse: tuple[bool, ...] = ()
    robot: str | None = None

    def __post_init__(self) -> None:
        if self.reverse and len(self.reverse) != len(self.tasks):
            raise ValueError(
                f"lot {self.id}: {len(self.reverse)} directions for {len(self.tasks)} tasks"
            )

    def driven(self, backwards: bool) -> list[tuple[str, bool]]:
        """(task id, driven backwards) in the order a winner drives them, bought ``backwards``
        (entered at :attr:`exit`) or not."""
        pairs = list(zip(self.tasks, self.reverse or (False,) * len(self.tasks), strict=True))
        if backwards:
            return [(t, not r) for t, r in reversed(pairs)]
        return pairs


def task_lot(task: Task) -> Lot:
    return Lot(task.id, (task.id,), task.entry, task.exit, task.time_s, task.area_m2)


def region_lot(lot_id: str, region: Region, tasks: Mapping[str, Task], robot: str) -> Lot:
    """A compact region sold to ``robot`` alone: its tasks in its driving order and directions,
    entered where its first task's drive begins; its time is the region's less the travel from
    the robot's start to it, which the robot's bid adds."""
    if not region.tasks:
        raise ValueError(f"lot {lot_id}: a region without tasks")
    own = [tasks[t] for t in region.tasks]
    first, last = own[0], own[-1]
    return Lot(
        lot_id,
        region.tasks,
        first.exit if region.reverse[0] else first.entry,
        last.entry if region.reverse[-1] else last.exit,
        float(region.time_s - region.start_s),
        float(sum(t.area_m2 for t in own)),
        reverse=region.reverse,
        robot=robot,
    )


def regions(tasks: Sequence[Task], k: int, prefix: str = "region-") -> tuple[Lot, ...]:
    """Cut ``tasks`` (consecutive along one tour: each one's exit is the next one's entry) into
    at most ``k`` runs of about equal time: cut ``i`` at the task boundary nearest to ``i/k`` of
    the total time (never leaving a run empty). The transit between two runs' tasks is nil, so
    a run's time is the sum of its tasks'."""
    if k < 1:
        raise ValueError(f"k must be >= 1, got {k}")
    if not tasks:
        return ()
    times = np.array([t.time_s for t in tasks], dtype=float)
    ends = np.cumsum(times)
    cuts = [0]
    for i in range(1, min(k, len(tasks))):
        goal = ends[-1] * i / k
        cut = int(np.argmin(np.abs(ends - goal))) + 1
        cut = min(max(cut, cuts[-1] + 1), len(tasks) - (min(k, len(tasks)) - i))
        cuts.append(cut)
    cuts.append(len(tasks))
    out = []
    for n, (a, b) in enumerate(itertools.pairwise(cuts)):
        run = tasks[a:b]
        out.append(
            Lot(
                f"{prefix}{n}",
                tuple(t.id for t in run),
                run[0].entry,
                run[-1].exit,
                float(times[a:b].sum()),
                float(sum(t.area_m2 for t in run)),
            )
        )
    return tuple(out)
