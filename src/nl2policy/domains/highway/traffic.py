"""The other cars of the highway twin: who is ahead and behind in each lane, IDM acceleration and
MOBIL lane changes, for every car of every episode at once (highway-env's ``IDMVehicle``, rule by
rule; the scene, the ego car, kinematics and collisions are in ``twin.py``).

Each function reads the twin's state arrays, shape (envs, 1 + other cars), vehicle 0 the ego;
``lane_changes`` also sets the cars' target lanes and lane-change timers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Optional

import numpy as np

from .geometry import IDM, LANE_WIDTH, RoadOrder, not_zero

if TYPE_CHECKING:
    from .twin import HighwayTwin


class Cars:
    """What IDM reads of a car, for every car plus a "no car" column (index v), gathered by
    index arrays with one flat take: built once a frame, not once a query."""

    FIELDS = ("x", "vx", "vy", "speed", "target", "cos", "sin")  # what a front car needs comes first
    FRONT = 3

    def __init__(self, twin: HighwayTwin) -> None:
        n, v = twin.x.shape
        self.v = v
        self.base = np.arange(n)[:, None] * (v + 1)
        cos, sin = np.cos(twin.heading), np.sin(twin.heading)
        target = np.abs(not_zero(np.clip(twin.target_speed, 0, twin.config.speed_limit)))
        table = np.zeros((len(self.FIELDS), n, v + 1))
        for k, values in enumerate((twin.x, twin.speed * cos, twin.speed * sin, twin.speed, target, cos, sin)):
            table[k, :, :v] = values
        table[4, :, v] = 1.0  # "no car" has a harmless target speed; its results are masked out
        self.flat = table.reshape(len(self.FIELDS), -1)
        self.own = table[:, :, :v]  # each car itself, without a copy
        self.free_own = IDM.COMFORT_ACC_MAX * (1 - np.power(np.maximum(twin.speed, 0) / target, twin.delta))

    def take(self, index: np.ndarray, fields: int = len(FIELDS)) -> np.ndarray:
        """(fields, n, v): the first `fields` fields of car index[n, i]."""
        return self.flat[:fields, self.base + index]


def lane_neighbours(twin: HighwayTwin, order: RoadOrder) -> tuple[np.ndarray, np.ndarray]:
    """front[l, n, i] / rear[l, n, i]: the nearest car ahead of / behind car i among the cars
    on lane l (within half a lane plus 1 m of its centre: Lane.on_lane with margin 1), as
    ``Road.neighbour_vehicles(i, lane l)`` finds them; ``twin.v`` where there is none."""
    lanes = twin.config.lanes
    front = np.empty((lanes, twin.num_envs, twin.v), dtype=np.int64)
    rear = np.empty_like(front)
    for lane in range(lanes):
        on = np.abs(twin.y - lane * LANE_WIDTH) <= LANE_WIDTH / 2 + 1
        front[lane], rear[lane] = order.ahead(on), order.behind(on)
    return front, rear


def desired_gap(e: np.ndarray, f: np.ndarray) -> np.ndarray:
    """IDMVehicle.desired_gap for gathered cars e (ego) and f (front), velocities projected
    on the ego's heading."""
    _, vx, vy, speed, _, cos, sin = e
    dv = (vx - f[1]) * cos + (vy - f[2]) * sin
    ab = -IDM.COMFORT_ACC_MAX * IDM.COMFORT_ACC_MIN
    return IDM.DISTANCE_WANTED + speed * IDM.TIME_WANTED + speed * dv / (2 * np.sqrt(ab))


def idm(cars: Cars, ego: Optional[np.ndarray], front: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """IDMVehicle.acceleration(ego_vehicle=ego, front_vehicle=front), with the deciding car's
    exponent `delta`; 0 where there is no ego car (index ``cars.v``). ``ego=None`` means each
    car itself, deciding for itself (its free-road term is computed once a frame)."""
    f = cars.take(front, Cars.FRONT)
    if ego is None:
        e, accel = cars.own, cars.free_own
    else:
        e = cars.take(ego)
        accel = IDM.COMFORT_ACC_MAX * (1 - np.power(np.maximum(e[3], 0) / e[4], delta))
    interaction = IDM.COMFORT_ACC_MAX * np.power(desired_gap(e, f) / not_zero(f[0] - e[0]), 2)
    accel = np.where(front < cars.v, accel - interaction, accel)
    return accel if ego is None else np.where(ego < cars.v, accel, 0.0)


def lane_changes(twin: HighwayTwin, cars: Cars, order: RoadOrder, follow: np.ndarray, rear: np.ndarray) -> None:
    """IDMVehicle.change_lane_policy for every other car at once: abort a change that
    another merging car makes unsafe, else every LANE_CHANGE_DELAY ask MOBIL about the lane
    to the left, then to the right (a yes to the right wins)."""
    n, v, lanes = twin.num_envs, twin.v, twin.config.lanes
    driven = (np.arange(v)[None, :] > 0) & ~twin.crashed  # the other cars, still driving
    changing = driven & (twin.lane != twin.target_lane)

    # Abort: a car already heading for my target lane from another lane, close ahead.
    merging = (twin.lane != twin.target_lane)  # any car, the ego included
    merging_ahead = np.full((n, v), v, dtype=np.int64)
    for lane in range(lanes):
        merging_ahead = np.where(twin.target_lane == lane, order.ahead(merging & (twin.target_lane == lane)),
                                 merging_ahead)
    me = np.broadcast_to(np.arange(v), (n, v))
    e, f = cars.own, cars.take(merging_ahead, Cars.FRONT)
    distance = f[0] - e[0]
    abort = changing & (merging_ahead < v) & (distance > 0) & (distance < desired_gap(e, f))
    twin.target_lane = np.where(abort, twin.lane, twin.target_lane)

    # MOBIL, at its own pace.
    due = driven & ~changing & (twin.timer > IDM.LANE_CHANGE_DELAY)
    twin.timer = np.where(due, 0.0, twin.timer)
    ask = due & (np.abs(twin.speed) >= 1)
    if not ask.any():
        return
    rows = np.arange(n)[:, None]
    self_a = follow[twin.lane, rows, me]
    new_target = twin.target_lane.copy()
    for step in (-1, 1):
        candidate = twin.lane + step
        valid = ask & (candidate >= 0) & (candidate < lanes)
        lane = np.clip(candidate, 0, lanes - 1)
        new_rear = rear[lane, rows, me]
        # Would my new follower have to brake too hard?
        follower_a = idm(cars, new_rear, me, twin.delta)
        safe = follower_a >= -IDM.LANE_CHANGE_MAX_BRAKING_IMPOSED
        # Do I gain enough (politeness 0: only my own acceleration counts)?
        gain = follow[lane, rows, me] - self_a
        new_target = np.where(valid & safe & (gain >= IDM.LANE_CHANGE_MIN_ACC_GAIN), lane, new_target)
    twin.target_lane = new_target
