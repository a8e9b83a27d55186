"""The coordinator's features as parts: what one adds to the service and to the market.

The coordinator (:class:`fleet.coordinator.service.Coordinator`) runs the job and the market
(:class:`fleet.coordinator.market.Market`) sells it; a feature is a :class:`Part` handed to
both, never a kind of coordinator, so any combination runs: batteries
(:class:`fleet.coordinator.charging_part.ChargingPart`), exploring
(:class:`fleet.coordinator.explore_part.ExplorePart`), the check of a stored map and its
changes (:class:`fleet.coordinator.map_watch.MapWatch`). :func:`fleet.coordinator.build.
build_coordinator` picks them from the configuration.

A part implements the hooks it needs; every hook of :class:`Part` does nothing. The service
and the market call them through :class:`Parts`, which says how the answers of several parts
combine. Hooks are called with the coordinator's lock held, except :meth:`Part.wire`,
:meth:`Part.serve`, :meth:`Part.start`, :meth:`Part.make_tasks` (which takes it) and
:meth:`Part.unlocked`.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from typing import Protocol, TypeVar

from fleet.bus import Bus
from fleet.coordinator.awards import Awards
from fleet.coordinator.dispatcher import Dispatcher
from fleet.coordinator.job import Job
from fleet.coordinator.journal import Journal
from fleet.coordinator.market import Cut, Market
from fleet.coordinator.planning import TaskPlanner
from fleet.params import CoordinatorParams
from fleet.protocol import Keys, RobotStatus
from planners import auction

# the phase of a coordinator at work once the first allocation is sold, unless a part names
# another
WORKING = "cleaning"


class Host(Protocol):
    """What a part may use of the coordinator it is wired into."""

    bus: Bus
    keys: Keys
    params: CoordinatorParams
    expected: int
    planner: TaskPlanner
    job: Job
    journal: Journal
    awards: Awards
    dispatcher: Dispatcher
    market: Market
    lock: threading.RLock
    wake: threading.Event
    stop: threading.Event

    def implausible(self, key: str, rid: str, stamp: float | None = None) -> bool: ...

    def work_over(self) -> bool: ...


class Part:
    """A feature of the coordinator: the hooks the service and the market call, each a no-op
    here."""

    # the coordinator's phase at work, once the first allocation is sold (None: "cleaning")
    working: str | None = None
    # whether the floor plan the tasks are cut from is served on coord/map
    floor_plan = True

    # ---- the service's hooks ----------------------------------------------------------------

    def wire(self, host: Host) -> None:
        """Make what the part needs of the coordinator's parts, before any message is
        heard."""

    def serve(self) -> None:
        """Subscribe and serve the part's keys (the coordinator's receivers are ready)."""

    def make_tasks(self) -> bool:
        """Make the job's tasks instead of the floor's tour; whether it did."""
        return False

    def start(self) -> None:
        """The coordinator's main loop starts."""

    def observe(self, rid: str, msg: RobotStatus) -> None:
        """A status report from ``rid``, after the market's stall watch took it."""

    def check_stalls(self) -> None:
        """Each loop after the market's stall watch: the part's own."""

    def tick(self) -> None:
        """What the part does each loop (with the lock held)."""

    def unlocked(self) -> None:
        """What the part does each loop without the lock (work heartbeats must not wait
        for)."""

    def work_over(self, job: Job) -> bool | None:
        """Whether the job's work is over, when the part decides it (None: every task is done
        or left out, ``Job.finished``, decides)."""
        return None

    def settled(self) -> bool:
        """Whether a job whose work is over may end now (robots still on their way home hold
        it up)."""
        return True

    def refusal(self) -> str | None:
        """Why the part stopped the coordinator, if it did."""
        return None

    # ---- the market's hooks -----------------------------------------------------------------

    def regions(self, first: bool, cut: Cut) -> tuple[bool, Cut]:
        """Whether this is the first allocation and how its regions are cut, as the part
        changes them."""
        return first, cut

    def lots(self) -> dict[str, auction.Lot] | None:
        """What the next round sells, when the part decides it (None: the regions, then the
        open tasks)."""
        return None

    def may_win(self, lot: auction.Lot, robot: str) -> bool:
        """Whether ``robot`` may win ``lot`` as far as the part goes."""
        return True

    def estimate_first(self, committed: list[float]) -> bool:
        """Tell the job's estimate from the first allocation; whether the part did."""
        return False

    def after_auction(self, sold: int) -> None:
        """An auction ended, having sold ``sold`` lots."""


P = TypeVar("P", bound=Part)


class Parts:
    """The coordinator's parts as one: each hook called on every part in order, and the answers
    combined (a phase, a task maker, a job's end, lots: the first part with one; may win, may
    end: every part agrees; regions: each part's change of the one before)."""

    def __init__(self, parts: Sequence[Part] = ()) -> None:
        self.all = tuple(parts)

    def of(self, kind: type[P]) -> P | None:
        """The part of type ``kind``, if the coordinator has one."""
        return next((p for p in self.all if isinstance(p, kind)), None)

    @property
    def working(self) -> str:
        return next((p.working for p in self.all if p.working is not None), WORKING)

    @property
    def floor_plan(self) -> bool:
        return all(p.floor_plan for p in self.all)

    def wire(self, host: Host) -> None:
        for p in self.all:
            p.wire(host)

    def serve(self) -> None:
        for p in self.all:
            p.serve()

    def make_tasks(self) -> bool:
        return any(p.make_tasks() for p in self.all)

    def start(self) -> None:
        for p in self.all:
            p.start()

    def observe(self, rid: str, msg: RobotStatus) -> None:
        for p in self.all:
            p.observe(rid, msg)

    def check_stalls(self) -> None:
        for p in self.all:
            p.check_stalls()

    def tick(self) -> None:
        for p in self.all:
            p.tick()

    def unlocked(self) -> None:
        for p in self.all:
            p.unlocked()

    def work_over(self, job: Job) -> bool:
        said = (p.work_over(job) for p in self.all)
        return next((over for over in said if over is not None), job.finished)

    def settled(self) -> bool:
        return all(p.settled() for p in self.all)

    def refusal(self) -> str | None:
        return next((why for p in self.all if (why := p.refusal()) is not None), None)

    def regions(self, first: bool, cut: Cut) -> tuple[bool, Cut]:
        for p in self.all:
            first, cut = p.regions(first, cut)
        return first, cut

    def lots(self) -> dict[str, auction.Lot] | None:
        return next((lots for p in self.all if (lots := p.lots()) is not None), None)

    def may_win(self, lot: auction.Lot, robot: str) -> bool:
        return all(p.may_win(lot, robot) for p in self.all)

    def estimate_first(self, committed: list[float]) -> bool:
        return any(p.estimate_first(committed) for p in self.all)

    def after_auction(self, sold: int) -> None:
        for p in self.all:
            p.after_auction(sold)
