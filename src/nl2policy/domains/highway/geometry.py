"""highway-env's constants and the array geometry the highway twin steps with.

Every constant is read from the highway-env class that owns it (a changed constant there changes
the twin too); the functions are highway-env's per-object rules (``utils.not_zero``,
``utils.wrap_to_pi``, ``utils.are_polygons_intersecting``) over arrays of cars, and ``RoadOrder``
finds each car's nearest neighbours along the road without comparing all pairs. Split from
``twin.py`` so that the twin's module holds the scene and its step, and this one the
geometry they are built from.
"""

from __future__ import annotations

import numpy as np
from highway_env.road.lane import StraightLane
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.controller import ControlledVehicle, MDPVehicle
from highway_env.vehicle.kinematics import Vehicle

# highway-env's constants, by the class that owns them.
LENGTH, WIDTH = Vehicle.LENGTH, Vehicle.WIDTH
DIAGONAL = float(np.sqrt(LENGTH**2 + WIDTH**2))
MAX_SPEED, MIN_SPEED = Vehicle.MAX_SPEED, Vehicle.MIN_SPEED
LANE_WIDTH = StraightLane.DEFAULT_WIDTH
ROAD_LENGTH = 10000.0  # RoadNetwork.straight_road_network's default length
KP_A, KP_HEADING, KP_LATERAL = ControlledVehicle.KP_A, ControlledVehicle.KP_HEADING, ControlledVehicle.KP_LATERAL
MAX_STEERING = ControlledVehicle.MAX_STEERING_ANGLE
TARGET_SPEEDS = np.asarray(MDPVehicle.DEFAULT_TARGET_SPEEDS, dtype=np.float64)
EGO_SPEED = 25.0  # HighwayEnv._create_vehicles: Vehicle.create_random(road, speed=25.0, ...)
IDM = IDMVehicle


def not_zero(x: np.ndarray, eps: float = 1e-2) -> np.ndarray:
    """highway_env.utils.not_zero, elementwise."""
    return np.where(np.abs(x) > eps, x, np.where(x >= 0, eps, -eps))


def wrap_to_pi(x: np.ndarray) -> np.ndarray:
    return ((x + np.pi) % (2 * np.pi)) - np.pi


def separating_axes(a: tuple, b: tuple, dt: float) -> tuple[np.ndarray, ...]:
    """utils.are_polygons_intersecting for pairs of car rectangles a, b = (x, y, heading, speed),
    each a 1-D array over pairs: (intersecting, will intersect within dt, translation x, y).

    The axes are each rectangle's four edge normals in the polygon's order, the ego's first: the
    translation is along the first axis of least |distance|, as there."""
    ax_, ay_, ah, aspeed = a
    bx, by, bh, bspeed = b
    ac, as_, bc, bs = np.cos(ah), np.sin(ah), np.cos(bh), np.sin(bh)
    sweep_x, sweep_y = (aspeed * ac - bspeed * bc) * dt, (aspeed * as_ - bspeed * bs) * dt
    centre_dx, centre_dy = ax_ - bx, ay_ - by

    def project(cx, cy, c, s, nx, ny):
        centre = cx * nx + cy * ny
        extent = LENGTH / 2 * np.abs(c * nx + s * ny) + WIDTH / 2 * np.abs(-s * nx + c * ny)
        return centre - extent, centre + extent

    def interval_distance(min_a, max_a, min_b, max_b):
        return np.where(min_a < min_b, min_b - max_a, min_a - max_b)

    intersecting = np.ones(ax_.shape, dtype=bool)
    will = np.ones(ax_.shape, dtype=bool)
    best = np.full(ax_.shape, np.inf)
    axis_x, axis_y = np.zeros(ax_.shape), np.zeros(ax_.shape)
    for c, s in ((ac, as_), (bc, bs)):
        for nx, ny in ((-c, -s), (-s, c), (c, s), (s, -c)):
            min_a, max_a = project(ax_, ay_, ac, as_, nx, ny)
            min_b, max_b = project(bx, by, bc, bs, nx, ny)
            intersecting &= interval_distance(min_a, max_a, min_b, max_b) <= 0
            sweep = nx * sweep_x + ny * sweep_y
            min_a, max_a = np.where(sweep < 0, min_a + sweep, min_a), np.where(sweep < 0, max_a, max_a + sweep)
            distance = interval_distance(min_a, max_a, min_b, max_b)
            will &= distance <= 0
            closer = np.abs(distance) < best
            best = np.where(closer, np.abs(distance), best)
            sign = np.where(centre_dx * nx + centre_dy * ny > 0, 1.0, -1.0)
            axis_x, axis_y = np.where(closer, sign * nx, axis_x), np.where(closer, sign * ny, axis_y)
    return intersecting, will, best * axis_x, best * axis_y


class RoadOrder:
    """The cars of each episode sorted by position along the road, to find for every car the
    nearest car ahead or behind that meets a condition with one running min (or max) over the
    sorted order: O(cars log cars) per episode, where comparing all pairs is O(cars^2)."""

    def __init__(self, x: np.ndarray) -> None:
        n, v = x.shape
        self.v = v
        self.rows = np.arange(n)[:, None]
        self.order = np.argsort(x, axis=1, kind="stable")  # sorted position -> car
        self.rank = np.empty_like(self.order)  # car -> sorted position
        self.rank[self.rows, self.order] = np.arange(v)
        self.order_padded = np.concatenate([self.order, np.full((n, 1), v)], axis=1)
        self.positions = np.arange(v)
        self.none = np.full((n, 1), v)

    def _to_cars(self, position: np.ndarray) -> np.ndarray:
        """For each car (by sorted position) the car at `position` (v = none), back in car order."""
        return self.order_padded[self.rows, position][self.rows, self.rank]

    def ahead(self, mask: np.ndarray) -> np.ndarray:
        """For each car, the nearest car strictly after it in the order with `mask` set."""
        on = mask[self.rows, self.order]
        nearest = np.minimum.accumulate(np.where(on, self.positions, self.v)[:, ::-1], axis=1)[:, ::-1]
        return self._to_cars(np.concatenate([nearest[:, 1:], self.none], axis=1))

    def behind(self, mask: np.ndarray) -> np.ndarray:
        """For each car, the nearest car strictly before it in the order with `mask` set."""
        on = mask[self.rows, self.order]
        nearest = np.maximum.accumulate(np.where(on, self.positions, -1), axis=1)
        nearest = np.concatenate([np.full_like(self.none, -1), nearest[:, :-1]], axis=1)
        return self._to_cars(np.where(nearest < 0, self.v, nearest))
