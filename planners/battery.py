"""A robot's battery: what drains it, what charges it, and what a task costs of it.

Charge is a fraction of a full battery. ``capacity_s`` is how long a full charge lasts sweeping
(driving at top speed with the brush on); the drain splits that into the wheels (scaled by how
fast they turn), the brush (while the robot moves) and the electronics (always), each a share
of the sweeping drain, so the three shares add up to 1. A dock puts back ``charge_rate``
seconds of sweeping per second. This is the linear state-of-charge (Coulomb-counting) model of
the fleet managers robots are run by (Open-RMF's battery-aware task planner prices a task the
same way: energy for the motion, for the device, and for the ambient load over its duration).

The market's energy check (:func:`can_take`) prices work at the sweeping drain, the most a
second of it can cost, so a robot that bids on a task can finish it and get home to a dock.

A dock charges one robot at a time, so the charge a robot needs to get home is not a fixed
reserve: :func:`go_home_below` adds to ``recharge_threshold`` (the margin it arrives with) the
trip at the sweeping drain and the wait behind the robots ahead of it at that dock (each
charging from its charge to ``recharge_to``) at the idle drain — the reserve of Open-RMF's
battery-aware planner, with the dock's queue counted as a ``wait`` task before the charge.

Robots at work that fall due together compete for the docks: :func:`go_home_points` counts
their go-home points together (list scheduling in the order they fall due, each counting the
earlier ones still at a dock when it falls due), and :func:`pick_dock` sends a robot to the dock
its charge covers that it is on soonest, trip and wait counted.

:func:`makespan_with_charging` is the job's makespan with the charges in it: each robot works
down to ``recharge_threshold`` plus its trip to the dock, drives there, queues for the first
free dock (first come, first served), charges to ``recharge_to``, drives back and works on,
and drives home at the end — a discrete-event simulation of the docks as servers of a queue,
every second of work and trip priced at the sweeping drain as :func:`can_take` prices it.

:func:`charge_early` staggers the charges at a dock: robots that would fall due together are
sent one by one while the dock is free, each late enough to be charged and off it before the
next falls due (latest start times counted back from the last one's go-home point).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planners.checks import require_non_negative, require_positive

Pose = tuple[float, float, float]


@dataclass(frozen=True)
class BatterySpec:
    """``enabled``: whether the robot runs down (off: it never does, as before batteries);
    ``capacity_s`` (s) of sweeping a full charge lasts; ``drive_share``, ``brush_share`` and
    ``idle_share``: the shares of the sweeping drain the wheels (at top speed), the brush (while
    moving) and the electronics (always) take, adding up to 1; ``charge_rate``: seconds of
    sweeping a dock puts back per second; ``recharge_threshold``: below this fraction the
    robot goes to charge; ``recharge_to``: it charges up to this fraction before it works
    again; ``dock_tolerance`` (m) and ``dock_align`` (rad): how near the dock's pose its centre
    and how near the docking heading (facing the dock) its heading must be for it to charge;
    ``start_charge``: the fraction of a full charge a robot starts with (the simulator's: the
    coordinator and the agent learn it from the battery's readings)."""

    enabled: bool = False
    capacity_s: float = 3600.0
    drive_share: float = 0.5
    brush_share: float = 0.3
    idle_share: float = 0.2
    charge_rate: float = 4.0
    recharge_threshold: float = 0.2
    recharge_to: float = 0.9
    dock_tolerance: float = 0.12
    dock_align: float = 0.8
    start_charge: float = 1.0

    def validate(self) -> None:
        require_positive(self, "capacity_s", "charge_rate", "dock_tolerance", "dock_align")
        require_non_negative(self, "drive_share", "brush_share", "idle_share")
        total = self.drive_share + self.brush_share + self.idle_share
        if not math.isclose(total, 1.0, abs_tol=1e-6):
            raise ValueError(
                f"drive_share + brush_share + idle_share must add up to 1 (they add up to "
                f"{total:g}): capacity_s is the time a full charge lasts sweeping"
            )
        if not 0 <= self.recharge_threshold < 1:
            raise ValueError(f"recharge_threshold ({self.recharge_threshold}) must be in [0, 1)")
        if not self.recharge_threshold < self.recharge_to <= 1:
            raise ValueError(
                f"recharge_to ({self.recharge_to}) must be in (recharge_threshold, 1]: a robot "
                "charges to above the level that sends it to charge"
            )
        if not 0 < self.start_charge <= 1:
            raise ValueError(f"start_charge ({self.start_charge}) must be in (0, 1]")
        if self.dock_align > math.pi:
            raise ValueError(f"dock_align ({self.dock_align}) must be at most pi")


def drain_per_s(
    spec: BatterySpec, v: np.ndarray, w: np.ndarray, max_v: float, wheel_base: float
) -> np.ndarray:
    """Fraction of a full charge used per second by robots driving at ``v`` (m/s), ``w``
    (rad/s): the faster wheel's speed over the top speed drives the wheels' share (a turn in
    place turns them too), the brush runs while the robot moves, the electronics always."""
    wheel = np.minimum((np.abs(v) + np.abs(w) * wheel_base / 2) / max_v, 1.0)
    moving = (np.abs(v) > 1e-3) | (np.abs(w) > 1e-3)
    share = spec.idle_share + spec.brush_share * moving + spec.drive_share * wheel
    return share / spec.capacity_s


def charge_per_s(spec: BatterySpec) -> float:
    """Fraction of a full charge a dock puts back per second."""
    return spec.charge_rate / spec.capacity_s


def docking_heading(dock: Pose) -> float:
    """The heading of a robot on ``dock``: facing the dock's body (its contacts), the opposite
    of the dock's pose, which faces away from the wall."""
    return math.atan2(-math.sin(dock[2]), -math.cos(dock[2]))


def on_dock(spec: BatterySpec, poses: np.ndarray, dock: Pose) -> np.ndarray:
    """Which of the robots at ``poses`` ((N, 3)) stand on ``dock``: centre within
    ``dock_tolerance`` of its pose and heading within ``dock_align`` of facing it."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    near = np.hypot(poses[:, 0] - dock[0], poses[:, 1] - dock[1]) <= spec.dock_tolerance
    off = np.angle(np.exp(1j * (poses[:, 2] - docking_heading(dock))))
    return near & (np.abs(off) <= spec.dock_align)


def work_charge(spec: BatterySpec, seconds: float) -> float:
    """Fraction of a full charge ``seconds`` of work (driving, sweeping) can use at most."""
    return max(seconds, 0.0) / spec.capacity_s


def can_take(spec: BatterySpec, charge: float, work_s: float, home_s: float) -> bool:
    """Whether a robot with ``charge`` can do ``work_s`` seconds of work (all it has won and
    the task it bids on, with the travel between) and then drive ``home_s`` seconds to a dock
    without running out, each second priced at the sweeping drain. Always, with batteries
    off."""
    if not spec.enabled:
        return True
    return charge - work_charge(spec, work_s + home_s) >= 0.0


def queue_wait_s(spec: BatterySpec, ahead: Sequence[float]) -> float:
    """Seconds a robot waits at a dock behind robots charged ``ahead`` (charging there, or on
    their way or waiting), each charging to ``recharge_to`` at ``charge_rate`` in turn."""
    need = sum(max(spec.recharge_to - max(c, 0.0), 0.0) for c in ahead)
    return need / charge_per_s(spec)


def go_home_below(spec: BatterySpec, trip_s: float, ahead: Sequence[float]) -> float:
    """The charge below which a robot goes to charge now: ``recharge_threshold`` kept on
    arrival, plus its ``trip_s`` seconds to the dock at the sweeping drain, plus its wait
    behind ``ahead`` (:func:`queue_wait_s`) standing, at the electronics' drain. 0 with
    batteries off."""
    if not spec.enabled:
        return 0.0
    wait = queue_wait_s(spec, ahead) * spec.idle_share / spec.capacity_s
    return spec.recharge_threshold + work_charge(spec, trip_s) + wait


def makespan_with_charging(
    spec: BatterySpec,
    work_s: Sequence[float],
    charges: Sequence[float],
    docks: int,
    trips_s: Sequence[float] | None = None,
) -> float:
    """When the last robot finishes its ``work_s`` (one entry per robot) from its charge
    (``charges``, same order) and is home, counting the charges on the way: a robot works until
    its charge is at ``recharge_threshold`` plus its trip to the dock (``trips_s``, seconds
    each way between its work and a dock; none: 0), drives there, takes the dock that frees
    first of ``docks`` (robots in the order they arrive), waits there at the electronics'
    drain, charges to ``recharge_to`` at ``charge_rate``, drives back and works on; at the end
    it drives home. Work and trips are priced at the sweeping drain. With batteries off, or no
    dock, the longest work; ``math.inf`` when a robot charged to ``recharge_to`` cannot get to
    its work and back with the threshold left (it would shuttle for ever)."""
    trips = [0.0] * len(work_s) if trips_s is None else [max(t, 0.0) for t in trips_s]
    if not len(work_s) == len(charges) == len(trips):
        raise ValueError(f"{len(work_s)} work times for {len(charges)} charges, {len(trips)} trips")
    longest = max(work_s, default=0.0)
    if not spec.enabled or docks < 1:
        return longest
    free = [0.0] * docks  # when each dock is free again
    # (when it arrives at a dock or is home, robot, work left, charge)
    due: list[tuple[float, int, float, float]] = []
    for i, (w, c) in enumerate(zip(work_s, charges, strict=True)):
        charge = min(max(c, 0.0), 1.0)
        heapq.heappush(due, _next_event(spec, 0.0, i, max(w, 0.0), charge, trips[i]))
    end = 0.0
    while due:
        t, i, left, charge = heapq.heappop(due)
        if left <= 0.0:
            end = max(end, t)
            continue
        k = min(range(docks), key=free.__getitem__)
        start = max(t, free[k])
        arrived = max(charge - (start - t) * spec.idle_share / spec.capacity_s, 0.0)
        free[k] = start + (spec.recharge_to - arrived) / charge_per_s(spec)
        back = spec.recharge_to - work_charge(spec, trips[i])
        if back - work_charge(spec, trips[i]) <= spec.recharge_threshold:
            return math.inf
        heapq.heappush(due, _next_event(spec, free[k] + trips[i], i, left, back, trips[i]))
    return end


def _next_event(
    spec: BatterySpec, t: float, i: int, left: float, charge: float, trip_s: float
) -> tuple[float, int, float, float]:
    """Robot ``i`` works from ``t`` with ``left`` seconds of work on ``charge``, ``trip_s``
    from a dock: when it is home (nothing left after), or when it reaches the dock, having
    worked until its charge was the threshold plus the trip (the work left then)."""
    home = work_charge(spec, trip_s)
    reach = max(charge - spec.recharge_threshold - home, 0.0) * spec.capacity_s
    if left <= reach:
        return (t + left + trip_s, i, 0.0, charge - work_charge(spec, left) - home)
    return (t + reach + trip_s, i, left - reach, max(charge - work_charge(spec, reach) - home, 0.0))


def pick_dock(
    spec: BatterySpec, charge: float, trips_s: Sequence[float], ahead: Sequence[Sequence[float]]
) -> int | None:
    """The dock (index into ``trips_s``, the travel to each dock, inf where there is none) a
    robot with ``charge`` goes to charge at, ``ahead`` at each the charges of the robots before
    it there: of the docks its charge covers (:func:`go_home_below`), the one it is on soonest
    (trip + wait); when it covers none, the one that needs least charge. So a robot waits by
    the near dock behind another's charge when that costs less than crossing to a free one, and
    crosses when it is sooner and its charge covers the trip. None with no dock in reach."""
    options = [
        (go_home_below(spec, trip, ahead[k]), trip + queue_wait_s(spec, ahead[k]), k)
        for k, trip in enumerate(trips_s)
        if math.isfinite(trip)
    ]
    covered = [o for o in options if o[0] <= charge]
    if covered:
        return min(covered, key=lambda o: (o[1], o[0]))[2]
    return min(options, default=(0.0, 0.0, None))[2]


@dataclass(frozen=True)
class GoHome:
    """A robot at work as the go-home rule sees it: its ``charge`` and its ``trips_s`` (s) to
    each dock (inf where it has none)."""

    charge: float
    trips_s: tuple[float, ...]


def go_home_points(
    spec: BatterySpec, robots: Sequence[GoHome], ahead: Sequence[Sequence[float]]
) -> list[tuple[int, int | None, float]]:
    """Per robot of ``robots`` (at work, sharing the docks), in the order they fall due: its
    index, the dock it charges at when it falls due and its go-home point, the charge below
    which it goes now; ``ahead``: per dock, the charges of the robots already bound for it.

    A go-home point counted for the dock each robot would take alone breaks when robots fall
    due together: the one that loses the dock is sent on to wait or to the far dock on a reserve
    counted for a free near one. So the robots are list-scheduled (Graham 1969) in the order
    they fall due (their margin over their own cheapest dock as the docks stand): each counts,
    at every dock, the earlier robots that will still be there when it falls due (on their way,
    waiting or charging, each arriving with ``recharge_threshold`` and charging to
    ``recharge_to``), and its go-home point is the least :func:`go_home_below` over the docks
    with them counted: the near dock behind them, or a far one with its trip there. Falling
    due is timed at the sweeping drain, and a robot's own go-home point, which the robots
    counted can only raise, is found again until it stops changing. Counting the earlier robots
    can make a later one fall due first; so a second pass schedules them in the order the first
    pass's points put them, and each robot keeps the higher of its two points: robots falling
    due together count each other. Robots sent in the order of their margins over these points
    find the docks as their points counted them. With batteries off, or no dock in reach,
    (None, 0)."""
    if not spec.enabled:
        return [(i, None, 0.0) for i in range(len(robots))]
    none: list[list[float]] = [[] for _ in ahead]
    alone = [_cheapest(spec, r.trips_s, ahead, none)[0] for r in robots]
    first = _schedule(
        spec, robots, ahead, sorted(range(len(robots)), key=lambda i: robots[i].charge - alone[i])
    )
    second = _schedule(
        spec, robots, ahead, sorted(first, key=lambda i: robots[i].charge - first[i][1])
    )
    final = {i: max(first[i], second[i], key=lambda kp: kp[1]) for i in first}
    order = sorted(final, key=lambda i: robots[i].charge - final[i][1])
    return [(i, *final[i]) for i in order]


def _cheapest(
    spec: BatterySpec,
    trips_s: Sequence[float],
    ahead: Sequence[Sequence[float]],
    extra: Sequence[Sequence[float]],
) -> tuple[float, int | None]:
    """The least :func:`go_home_below` over the docks in reach, with ``ahead`` and ``extra``
    at each, and that dock."""
    return min(
        (
            (go_home_below(spec, trip, [*ahead[k], *extra[k]]), k)
            for k, trip in enumerate(trips_s)
            if math.isfinite(trip)
        ),
        default=(0.0, None),
    )


def _schedule(
    spec: BatterySpec,
    robots: Sequence[GoHome],
    ahead: Sequence[Sequence[float]],
    order: Sequence[int],
) -> dict[int, tuple[int | None, float]]:
    """One pass of :func:`go_home_points`: the robots in ``order``, each counting the earlier
    ones still at a dock when it falls due; per robot its dock and go-home point."""
    fill_s = (spec.recharge_to - spec.recharge_threshold) * spec.capacity_s / spec.charge_rate
    none: list[list[float]] = [[] for _ in ahead]
    out: dict[int, tuple[int | None, float]] = {}
    leaves: list[tuple[int, float]] = []  # (dock, when it is off it, s from now) of those before
    for i in order:
        trips = robots[i].trips_s
        point, k = _cheapest(spec, trips, ahead, none)
        extra: list[list[float]] = none
        for _ in range(len(robots) + 1):
            due_s = max(robots[i].charge - point, 0.0) * spec.capacity_s
            extra = [
                [spec.recharge_threshold for kj, off in leaves if kj == kk and off > due_s]
                for kk in range(len(ahead))
            ]
            again, k = _cheapest(spec, trips, ahead, extra)
            if again == point:
                break
            point = again
        out[i] = (k, point)
        if k is not None:
            wait_s = queue_wait_s(spec, [*ahead[k], *extra[k]])
            leaves.append((k, due_s + trips[k] + wait_s + fill_s))
    return out


@dataclass(frozen=True)
class DockUser:
    """A robot at work that will charge at a dock: its ``charge``, its ``trip_s`` to the dock
    and ``due_s``, the seconds of work (at the sweeping drain) until its charge falls to its
    go-home point (:func:`go_home_below`)."""

    charge: float
    trip_s: float
    due_s: float


def latest_leave_s(spec: BatterySpec, robot: DockUser, free_by_s: float) -> float:
    """The latest moment (s from now) ``robot`` can leave for the dock and be charged to
    ``recharge_to`` and off it by ``free_by_s``: leaving at ``s`` it arrives with its charge
    less ``s`` + its trip at the sweeping drain, so ``s + trip + (recharge_to - arrival) /
    charge rate <= free_by_s``, solved for ``s``. Never later than its own go-home point."""
    rate = spec.charge_rate
    fill_s = (spec.recharge_to - robot.charge) * spec.capacity_s / rate
    leave = (free_by_s - fill_s) / (1.0 + 1.0 / rate) - robot.trip_s
    return min(robot.due_s, leave)


def charge_early(spec: BatterySpec, robots: Sequence[DockUser]) -> int | None:
    """The robot (index into ``robots``, the robots at work that share one dock, which is free
    now and nobody is bound for) to send to charge now, before its go-home point, or None.

    Opportunistic charging, as fleet managers call it (a robot charges while the charger is
    free, before it must), timed by the backward pass of the critical-path method (latest
    start times, Kelley & Walker 1959): the robots take the dock in the order they fall due;
    the last may leave at its go-home point, and each earlier one must leave late enough to be
    charged and off the dock before the next one falls due (:func:`latest_leave_s`). When the
    first one's latest leave has come (or passed, the charges already overlapping) before its
    own go-home point, it goes now, so the charges are staggered instead of queued. A robot at
    or above ``recharge_to`` is never sent: the dock would give it nothing."""
    if not spec.enabled or len(robots) < 2:
        return None
    order = sorted(range(len(robots)), key=lambda i: robots[i].due_s)
    leave = robots[order[-1]].due_s
    for i in reversed(order[:-1]):
        leave = latest_leave_s(spec, robots[i], leave)
    first = robots[order[0]]
    if leave <= 0.0 < first.due_s and first.charge < spec.recharge_to:
        return order[0]
    return None
