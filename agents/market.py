"""The robot's side of the market: what it has won, what it bids, and what it has swept.

A robot prices a called task from what it knows — its own pose estimate, the plan it is
driving, the tasks it has won (its last :class:`~fleet.protocol.Award`) and its own SLAM map —
as the marginal cost of appending the task to its commitments (``planners.auction.make_bids``,
Koenig et al. 2006): all lots of a round in one go, answered in one message. Travel is priced
at ``agent.transit_speed`` on the floor plan the coordinator shares (``coord/map``), obstacles
grown by the robot's radius
(``planners.auction.TravelGrid``): at the first auction a robot has seen one room, and travel
priced on that alone would ignore every wall beyond it. Until it has the floor plan, on its own
SLAM map with unknown cells counted as free; before that, by the straight line. Transits are
priced at half the top speed because that is about what robots make on them (DWA slows in
doorways and along walls), while tasks' times come from the coverage plan: at top speed,
travel would look cheap next to the work a robot already holds, and an idle robot would win
tasks it takes far longer to reach than their owner would.

With batteries (``robot.battery``) a robot prices the energy too: a task it cannot finish, with
all it has won before it, and then drive home to the nearest dock from on its charge
(``planners.battery.can_take``) is declined, not bid for. While it charges (below
``recharge_to``) or has fallen below ``recharge_threshold`` it does not bid at all: the
coordinator has taken it out of the market.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agents.follow.state import FollowState
from agents.slam.slam_map import SlamMap
from fleet import plan_chain
from fleet.protocol import AuctionCall, Award, BatteryState, Bids
from planners import auction
from planners.battery import BatterySpec, can_take
from planners.grid import GridMap, dilate

# legs kept between queued tasks before they are forgotten all at once
MAX_LEGS = 4096


@dataclass(frozen=True)
class Won:
    """One task of the robot's queue, with its ends in the direction it will drive it."""

    id: str
    entry: tuple[float, float]
    exit: tuple[float, float]
    time_s: float


@dataclass(frozen=True, eq=False)
class _Priced:
    """An answer's prices, as :meth:`MarketClient._prices` keeps them for the next call."""

    travel: auction.Travel
    end: tuple[float, float]
    index: dict[str, int]
    entries: np.ndarray
    exits: np.ndarray
    times: np.ndarray
    gains: np.ndarray
    marginal: np.ndarray
    reverse: np.ndarray


class MarketClient:
    """The robot's queue and its pricing; not thread-safe (the agent holds its lock)."""

    def __init__(
        self,
        robot: str,
        speed: float,
        radius: float,
        occupied_threshold: float,
        free_threshold: float,
        battery: BatterySpec | None = None,
    ) -> None:
        self.robot = robot
        self.battery = battery if battery is not None else BatterySpec()
        # where the robot stands on each dock (K, 2), from the coordinator
        self.docks = np.zeros((0, 2))
        self.speed = speed
        self.radius = radius
        self.thresholds = (occupied_threshold, free_threshold)
        self.seq = 0
        self.queue: tuple[Won, ...] = ()
        self._travel: auction.Travel = self._straight
        self._travel_map: SlamMap | None = None
        self.has_floor = False
        # the last answer's prices, for the lots the next call sells again unchanged
        self._last: _Priced | None = None
        # lots priced anew (not taken from the last answer), all answers together
        self.priced = 0
        # travel between two points of the queue, on the travel grid it was priced on
        self._legs: dict[tuple[tuple[float, float], tuple[float, float]], float] = {}
        self._legs_on: auction.Travel | None = None

    def on_award(self, msg: Award) -> bool:
        """Take a newer award (True); an older or repeated one changes nothing."""
        if msg.robot != self.robot or msg.seq <= self.seq:
            return False
        self.seq = msg.seq
        self.queue = tuple(
            Won(t, (float(e[0]), float(e[1])), (float(x[0]), float(x[1])), float(s))
            for t, e, x, s in zip(msg.tasks, msg.entries, msg.exits, msg.times_s, strict=True)
        )
        return True

    def holds(self, task: str) -> bool:
        return any(w.id == task for w in self.queue)

    def use_floor(self, floor: GridMap) -> None:
        """Price travel on the floor plan from now on (outside it counts as blocked)."""
        self._travel = auction.floor_travel(floor, self.radius, self.speed)
        self.has_floor = True

    def use_map(self, occupancy: SlamMap | None) -> None:
        """Without the floor plan, price travel on this SLAM map (rebuilt only when it is a new
        snapshot)."""
        if self.has_floor or occupancy is None or occupancy is self._travel_map:
            return
        grid = occupancy.to_gridmap(*self.thresholds)
        blocked = dilate(grid.occupied, self.radius, grid.resolution)
        self._travel = auction.TravelGrid(~blocked, grid.resolution, grid.origin, self.speed)
        self._travel_map = occupancy

    def commitment(
        self,
        pose: tuple[float, float, float],
        follow: FollowState | None,
        chain: list[str],
        chain_time_s: float,
    ) -> auction.Commitment:
        """What the robot has won, priced from ``pose``: the rest of the plan it drives for the
        tasks of ``chain`` (their ``chain_time_s`` scaled by the length left), then its other
        queued tasks with the travel to each."""
        xy = (float(pose[0]), float(pose[1]))
        items = list(self.queue)
        current = auction.Commitment(xy)
        if items and follow is not None and not follow.done and items[0].id in chain:
            wps = follow.waypoints
            left = math.dist(xy, wps[follow.index]) + _length(wps[follow.index :])
            total = max(_length(wps), 1e-9)
            end = (float(wps[-1][0]), float(wps[-1][1]))
            current = auction.Commitment(xy, chain_time_s * min(left / total, 1.0), end)
            items = [w for w in items if w.id not in chain]
        for w in items:
            current = current.with_task(w.entry, w.exit, w.time_s, self._leg(current.end, w.entry))
        return current

    def _leg(self, start: tuple[float, float], end: tuple[float, float]) -> float:
        """Seconds from ``start`` to ``end``, kept: between two awards the legs between queued
        tasks stay as they are, and every answer prices the queue again (a 24-task queue
        cost 5 ms an answer)."""
        if self._legs_on is not self._travel or len(self._legs) > MAX_LEGS:
            self._legs_on, self._legs = self._travel, {}
        key = (start, end)
        if key not in self._legs:
            self._legs[key] = float(self._travel(np.array(start), np.array([end]))[0])
        return self._legs[key]

    def resting(self, reading: BatteryState | None) -> bool:
        """Whether the robot is out of the market on its charge: below the threshold, or
        charging and not yet at ``recharge_to``."""
        spec = self.battery
        if not spec.enabled or reading is None:
            return False
        low = reading.percentage < spec.recharge_threshold
        return low or (reading.charging and reading.percentage < spec.recharge_to)

    def home_times(self, points: np.ndarray) -> np.ndarray:
        """Seconds from each of ``points`` (K, 2) to its nearest dock (0 without docks known),
        priced from the docks: one graph search a dock, not one a point (the travel graph is
        undirected)."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        if not len(self.docks):
            return np.zeros(len(points))
        return np.min([self._travel(dock, points) for dock in self.docks], axis=0)

    def bids(
        self,
        call: AuctionCall,
        commitment: auction.Commitment,
        reading: BatteryState | None = None,
    ) -> Bids:
        """This robot's answer to ``call``: its bids on the lots it does not already hold, all
        priced in one go (``planners.auction.make_bids``); with its battery's ``reading``, those
        it cannot do and then get home from are declined. No lots while it rests on its charge."""
        held = {w.id for w in self.queue}
        keep = np.array([lot not in held for lot in call.lots], dtype=bool)
        lots = [lot for lot, k in zip(call.lots, keep, strict=True) if k]
        if self.resting(reading):
            keep[:], lots = False, []
        lot_ends = (call.entries[keep], call.exits[keep], call.times_s[keep], call.gains_s[keep])
        prices = self._prices(lots, *lot_ends, commitment)
        declined = np.zeros(len(lots), dtype=bool)
        if self.battery.enabled and lots:
            charge = 1.0 if reading is None else reading.percentage
            ends = np.where(prices.reverse[:, None], call.entries[keep], call.exits[keep])
            home = self.home_times(ends)
            declined = np.array(
                [
                    not can_take(self.battery, charge, float(t), float(h))
                    for t, h in zip(prices.total_s, home, strict=True)
                ]
            )
        return Bids(
            call.stamp,
            call.round,
            self.robot,
            lots,
            prices.marginal_s,
            prices.total_s,
            prices.reverse.astype(np.uint8),
            declined.astype(np.uint8),
        )

    def _prices(
        self,
        lots: list[str],
        entries: np.ndarray,
        exits: np.ndarray,
        times: np.ndarray,
        gains: np.ndarray,
        commitment: auction.Commitment,
    ) -> auction.Prices:
        """``planners.auction.make_bids`` for ``lots``, but a lot the last answer priced from
        the same end on the same travel grid, with the same ends, time and gain, keeps its
        price: a bid's marginal cost depends on nothing else, and between two rounds only the
        last winner's end moves (of 20 robots, 19 answer a round of 500 lots from memory)."""
        last = self._last
        old = np.full(len(lots), -1)
        if (
            last is not None
            and last.index
            and last.travel is self._travel
            and last.end == commitment.end
        ):
            old = np.array([last.index.get(lot, -1) for lot in lots], dtype=int)
            j = np.maximum(old, 0)
            same = (
                (last.entries[j] == entries).all(axis=1)
                & (last.exits[j] == exits).all(axis=1)
                & (last.times[j] == times)
                & (last.gains[j] == gains)
            )
            old = np.where(same, old, -1)
        new = old < 0
        fresh = auction.make_bids(
            entries[new], exits[new], times[new], commitment, self._travel, gains[new]
        )
        self.priced += int(new.sum())
        marginal = np.empty(len(lots))
        reverse = np.empty(len(lots), dtype=bool)
        marginal[new], reverse[new] = fresh.marginal_s, fresh.reverse
        if last is not None:
            marginal[~new], reverse[~new] = last.marginal[old[~new]], last.reverse[old[~new]]
        self._last = _Priced(
            self._travel,
            commitment.end,
            {lot: i for i, lot in enumerate(lots)},
            entries,
            exits,
            times,
            gains,
            marginal,
            reverse,
        )
        return auction.Prices(marginal, commitment.total_s + marginal, reverse)

    def _straight(self, start: np.ndarray, targets: np.ndarray) -> np.ndarray:
        return np.hypot(*(np.asarray(targets) - start).T) / self.speed


def swept_pieces(follow: FollowState | None, sweep_from: int) -> np.ndarray:
    """0/1 per piece of the plan ``follow`` drives (:func:`fleet.plan_chain.swept_pieces`)."""
    if follow is None:
        return np.zeros(0, dtype=np.uint8)
    return plan_chain.swept_pieces(len(follow.waypoints), sweep_from, follow.index, follow.missed)


def _length(points: np.ndarray) -> float:
    if len(points) < 2:
        return 0.0
    return float(np.hypot(*np.diff(points, axis=0).T).sum())
