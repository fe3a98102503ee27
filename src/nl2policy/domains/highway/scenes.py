"""Moving one scene between highway-env and the vectorized twin (twin.py), car by car.

Kept apart from the twin's simulation: these read and write highway-env's vehicle objects, which
the twin itself never touches. They serve the fidelity check (experiments/highway_fidelity.py:
both simulators run from the same scene) and watching a twin scene in highway-env's viewer.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .geometry import IDM
from .twin import HighwayTwin


def copy_scene_to(env: Any, twin: HighwayTwin, episode: int) -> None:
    """Put twin episode `episode`'s scene into a freshly reset highway-env env (``HighwayFeatures``
    or highway-env's own), car by car: to watch a twin scene in highway-env's viewer, and to
    check the twin against highway-env from the same scene."""
    highway = getattr(env, "highway", env)
    road = highway.road
    if len(road.vehicles) != twin.v:
        raise ValueError(f"highway-env has {len(road.vehicles)} cars, the twin {twin.v}")
    for i, car in enumerate(road.vehicles):
        car.position = np.array([twin.x[episode, i], twin.y[episode, i]])
        car.heading, car.speed = float(twin.heading[episode, i]), float(twin.speed[episode, i])
        car.lane_index = ("0", "1", int(twin.lane[episode, i]))
        car.lane = road.network.get_lane(car.lane_index)
        car.target_lane_index = ("0", "1", int(twin.target_lane[episode, i]))
        car.target_speed = float(twin.target_speed[episode, i])
        car.crashed, car.impact = bool(twin.crashed[episode, i]), None
        if i == 0:
            car.speed_index = car.speed_to_index(car.target_speed)
        else:
            car.DELTA, car.timer = float(twin.delta[episode, i]), float(twin.timer[episode, i])


def copy_scene_from(env: Any, twin: HighwayTwin, episode: int) -> None:
    """Put a freshly reset highway-env scene into twin episode `episode`, car by car (the
    reverse of ``copy_scene_to``): to replay highway-env's own episodes in the twin."""
    highway = getattr(env, "highway", env)
    cars = highway.road.vehicles
    if len(cars) != twin.v:
        raise ValueError(f"highway-env has {len(cars)} cars, the twin {twin.v}")
    twin.x[episode] = [car.position[0] for car in cars]
    twin.y[episode] = [car.position[1] for car in cars]
    twin.heading[episode] = [car.heading for car in cars]
    twin.speed[episode] = [car.speed for car in cars]
    twin.lane[episode] = [car.lane_index[2] for car in cars]
    twin.target_lane[episode] = [car.target_lane_index[2] for car in cars]
    twin.target_speed[episode] = [car.target_speed for car in cars]
    twin.delta[episode] = [IDM.DELTA] + [car.DELTA for car in cars[1:]]
    twin.timer[episode] = [0.0] + [car.timer for car in cars[1:]]
    twin.crashed[episode] = [car.crashed for car in cars]
    twin.impact_pending[episode] = False
    twin.time[episode] = 0
