"""The robot's side of the market: what it has won, what it bids, and what it has swept.

A robot prices a called task from what it knows — its own pose estimate, the plan it is
driving, the tasks it has won (its last :class:`~fleet.protocol.Award`) and its own SLAM map —
as the marginal cost of appending the task to its commitments (``planners.auction.make_bid``,
Koenig et al. 2006). Travel is priced at ``agent.transit_speed`` on the floor plan the
coordinator shares (``coord/map``), obstacles grown by the robot's radius
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
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agents.follow.state import FollowState
from agents.slam.slam_map import SlamMap
from fleet import plan_chain
from fleet.protocol import Award, BatteryState, Bid, TaskCall
from planners import auction
from planners.battery import BatterySpec, can_take
from planners.grid import GridMap, dilate


@dataclass(frozen=True)
class Won:
    """One task of the robot's queue, with its ends in the direction it will drive it."""

    id: str
    entry: tuple[float, float]
    exit: tuple[float, float]
    time_s: float


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
        blocked = dilate(floor.occupied | floor.unknown, self.radius, floor.resolution)
        self._travel = auction.TravelGrid(~blocked, floor.resolution, floor.origin, self.speed)
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
            travel = float(self._travel(np.array(current.end), np.array([w.entry]))[0])
            current = current.with_task(w.entry, w.exit, w.time_s, travel)
        return current

    def resting(self, reading: BatteryState | None) -> bool:
        """Whether the robot is out of the market on its charge: below the threshold, or
        charging and not yet at ``recharge_to``."""
        spec = self.battery
        if not spec.enabled or reading is None:
            return False
        low = reading.percentage < spec.recharge_threshold
        return low or (reading.charging and reading.percentage < spec.recharge_to)

    def home_s(self, xy: np.ndarray) -> float:
        """Seconds from ``xy`` to the nearest dock (0 without docks known)."""
        if not len(self.docks):
            return 0.0
        return float(np.min(self._travel(np.asarray(xy, dtype=float), self.docks)))

    def bids(
        self,
        calls: Sequence[TaskCall],
        commitment: auction.Commitment,
        reading: BatteryState | None = None,
    ) -> list[Bid]:
        """This robot's bids on ``calls`` (tasks it already holds are not bid on); with its
        battery's ``reading``, those it cannot do and then get home from are declined."""
        if self.resting(reading):
            return []
        charge = 1.0 if reading is None else reading.percentage
        out = []
        for c in calls:
            if self.holds(c.task):
                continue
            b = auction.make_bid(
                self.robot,
                c.task,
                np.array([c.entry_x, c.entry_y]),
                np.array([c.exit_x, c.exit_y]),
                c.time_s,
                commitment,
                self._travel,
                c.gain_s,
            )
            end = np.array([c.entry_x, c.entry_y] if b.reverse else [c.exit_x, c.exit_y])
            home = self.home_s(end) if self.battery.enabled else 0.0
            declined = not can_take(self.battery, charge, b.total_s, home)
            out.append(
                Bid(
                    c.stamp,
                    c.round,
                    c.task,
                    self.robot,
                    b.marginal_s,
                    b.total_s,
                    b.reverse,
                    declined,
                )
            )
        return out

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
