"""The pymunk world: static walls and furniture, disc robots with differential drive.

Robots are dynamic discs driven through joints to a kinematic control body, as in pymunk's
"tank" example: the control body moves at the commanded wheel velocities and a pivot and a gear
joint with bounded force pull the robot after it, so contacts win over the drive and a robot
pushing a wall stays outside it. Every new robot–wall or robot–robot contact is reported
through ``on_contact``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pymunk

from fleet.world import World

WALL = 1
ROBOT = 2
# Force and torque limits (per kg of robot) of the joints that drive a robot: strong enough to
# follow any commanded acceleration, weak against a wall's contact impulses.
DRIVE_FORCE_PER_KG = 30.0
DRIVE_TORQUE_PER_KG = 3.0


def static_shapes(world: World, body: pymunk.Body) -> list[pymunk.Shape]:
    """Poly shapes for a vector world; one box per horizontal run of occupied cells for a map."""
    shapes: list[pymunk.Shape] = []
    if world.map_grid is None:
        shapes = [pymunk.Poly(body, [tuple(p) for p in poly]) for poly in world.polygons]
    else:
        g = world.map_grid
        blocked = g.occupied | g.unknown
        pad = np.zeros((blocked.shape[0], 1), dtype=bool)
        edges = np.diff(np.hstack([pad, blocked, pad]).astype(np.int8), axis=1)
        starts = np.argwhere(edges == 1)
        ends = np.argwhere(edges == -1)
        res = g.resolution
        ox, oy = g.origin
        for (r, c0), (_, c1) in zip(starts, ends, strict=True):
            x0, x1 = ox + c0 * res, ox + c1 * res
            y0, y1 = oy + r * res, oy + (r + 1) * res
            shapes.append(pymunk.Poly(body, [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]))
    for s in shapes:
        s.collision_type = WALL
        s.friction = 0.0
    return shapes


class Physics:
    """A pymunk space holding the static world and the robot discs."""

    def __init__(self, world: World, on_contact: Callable[[str, str, float, float], None]) -> None:
        self.space = pymunk.Space()
        self.space.gravity = (0.0, 0.0)
        self.space.add(*static_shapes(world, self.space.static_body))
        self.bodies: dict[str, pymunk.Body] = {}
        self.controls: dict[str, pymunk.Body] = {}
        self._on_contact = on_contact
        self.space.on_collision(ROBOT, WALL, begin=self._begin)
        self.space.on_collision(ROBOT, ROBOT, begin=self._begin)

    def _begin(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: object) -> None:
        a, b = arbiter.shapes
        points = arbiter.contact_point_set.points
        x, y = (
            (points[0].point_a.x, points[0].point_a.y)
            if points
            else (a.body.position.x, a.body.position.y)
        )
        other = getattr(b, "robot_id", "") if b.collision_type == ROBOT else ""
        self._on_contact(a.robot_id, other, x, y)  # type: ignore[attr-defined]

    def add_robot(
        self, rid: str, pose: tuple[float, float, float], radius: float, mass: float
    ) -> None:
        body = pymunk.Body(mass, pymunk.moment_for_circle(mass, 0, radius))
        body.position = pose[0], pose[1]
        body.angle = pose[2]
        shape = pymunk.Circle(body, radius)
        shape.collision_type = ROBOT
        shape.friction = 0.0
        shape.elasticity = 0.0
        shape.robot_id = rid  # type: ignore[attr-defined]
        control = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        control.position = body.position
        pivot = pymunk.PivotJoint(control, body, (0, 0), (0, 0))
        pivot.max_bias = 0.0
        pivot.max_force = DRIVE_FORCE_PER_KG * mass
        gear = pymunk.GearJoint(control, body, 0.0, 1.0)
        gear.error_bias = 0.0
        gear.max_bias = 0.0
        gear.max_force = DRIVE_TORQUE_PER_KG * mass
        self.space.add(body, shape, control, pivot, gear)
        self.bodies[rid] = body
        self.controls[rid] = control

    def remove_robot(self, rid: str) -> None:
        body = self.bodies.pop(rid)
        control = self.controls.pop(rid)
        self.space.remove(body, *body.shapes, *body.constraints)
        self.space.remove(control)

    def drive(self, ids: list[str], v: np.ndarray, w: np.ndarray, headings: np.ndarray) -> None:
        """Command robots ``ids`` to (v, ω); ``headings`` are their current body angles."""
        vx = (v * np.cos(headings)).tolist()
        vy = (v * np.sin(headings)).tolist()
        controls = self.controls
        for rid, cx, cy, cw in zip(ids, vx, vy, w.tolist(), strict=True):
            control = controls[rid]
            control.velocity = (cx, cy)
            control.angular_velocity = cw

    def pose(self, rid: str) -> tuple[float, float, float]:
        body = self.bodies[rid]
        x, y = body.position
        return x, y, body.angle

    def poses(self, ids: list[str]) -> np.ndarray:
        """(N, 3) poses x, y, θ of robots ``ids``, in that order."""
        rows = []
        bodies = self.bodies
        for rid in ids:
            body = bodies[rid]
            x, y = body.position
            rows.append((x, y, body.angle))
        return np.array(rows, dtype=np.float64).reshape(-1, 3)

    def step(self, dt: float) -> None:
        self.space.step(dt)
