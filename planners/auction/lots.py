"""What one auction call sells: a single task, or a region of tasks.

The first allocation sells regions, one per robot, so each robot starts with a part of the floor
of its own, as a static split would give it (robots that interleave over the whole floor cross
each other's paths and drive over swept floor between tasks): the tour's tasks cut into runs
of about equal time (:func:`regions`). Everything sold later — a lost robot's remainder, tasks
withdrawn to feed an idle robot — goes task by task (:func:`task_lot`).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planners.auction.tasks import Task


@dataclass(frozen=True, eq=False)
class Lot:
    """One call's item: ``tasks`` in driving order from ``entry`` to ``exit``. A lot bought
    backwards (entered at its exit) is driven last task first, each task the other way round
    (:meth:`driven`). ``gain_s``: what it is worth beyond its work, in seconds a bid takes off
    (a frontier's expected information; 0 for cleaning)."""

    id: str
    tasks: tuple[str, ...]
    entry: np.ndarray
    exit: np.ndarray
    time_s: float
    area_m2: float
    gain_s: float = 0.0

    def driven(self, backwards: bool) -> list[tuple[str, bool]]:
        """(task id, driven backwards) in the order a winner drives them, bought ``backwards``
        (entered at :attr:`exit`) or not."""
        if backwards:
            return [(t, True) for t in reversed(self.tasks)]
        return [(t, False) for t in self.tasks]


def task_lot(task: Task) -> Lot:
    return Lot(task.id, (task.id,), task.entry, task.exit, task.time_s, task.area_m2)


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
