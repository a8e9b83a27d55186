"""The robots' batteries as the simulator keeps them: the truth of each one's charge.

Each step drains every robot by how it drives (``planners.battery.drain_per_s``) and charges
the one robot standing on each dock (``planners.battery.on_dock``: the first in the robots'
order, should two ever stand within the tolerance of one dock). A robot at 0 % stops: its
commands are ignored until a dock has put charge back. The figures the report reads (lowest
charge, charges begun, time on a dock) are kept per robot and outlive its departure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planners.battery import BatterySpec, charge_per_s, drain_per_s, on_dock
from planners.robot import RobotSpec

Pose = tuple[float, float, float]


@dataclass
class BatteryLog:
    """One robot's battery: its charge (fraction of a full one), the lowest it has been, how
    many times it began to charge, the sim seconds it spent charging, and whether it stands on
    a dock now (charging)."""

    charge: float = 1.0
    min_charge: float = 1.0
    charges: int = 0
    charging_s: float = 0.0
    docked: bool = False


class Batteries:
    """The charge of the robots in the world, one row per robot in the simulator's order."""

    def __init__(self, robot: RobotSpec, docks: tuple[Pose, ...]) -> None:
        self.spec: BatterySpec = robot.battery
        self.max_v = robot.max_vel_x
        self.wheel_base = robot.wheel_base
        self.docks = docks
        self.logs: list[BatteryLog] = []

    def add(self, log: BatteryLog) -> None:
        self.logs.append(log)

    def remove(self, row: int) -> BatteryLog:
        return self.logs.pop(row)

    def empty(self) -> np.ndarray:
        """Which robots (rows) have run out: they stand until charged."""
        return np.array([b.charge <= 0.0 for b in self.logs], dtype=bool)

    def step(self, dt: float, vel: np.ndarray, poses: np.ndarray) -> None:
        """Drain by the velocities ``vel`` ((N, 2) v, w), charge the robots on a dock."""
        if not self.logs:
            return
        drain = drain_per_s(self.spec, vel[:, 0], vel[:, 1], self.max_v, self.wheel_base) * dt
        charging = np.zeros(len(self.logs), dtype=bool)
        for dock in self.docks:
            on = np.flatnonzero(on_dock(self.spec, poses, dock) & ~charging)
            if len(on):
                charging[on[0]] = True
        gain = charge_per_s(self.spec) * dt
        for b, d, c in zip(self.logs, drain.tolist(), charging.tolist(), strict=True):
            if c:
                b.charges += not b.docked
                b.charging_s += dt
                b.charge = min(1.0, b.charge + gain)
            else:
                b.charge = max(0.0, b.charge - d)
                b.min_charge = min(b.min_charge, b.charge)
            b.docked = c
