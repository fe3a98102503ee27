"""A vectorized twin of the highway-env scene our highway domain uses, for training at real budgets.

highway-env steps one episode at a time through per-vehicle Python objects (about 27 env steps
a second here, ``results/benchmarks/env_steps.txt``). This module simulates the same scene,
``highway-fast-v0`` with our config, for N episodes at once: every quantity is an array of
shape (envs, vehicles), vehicle 0 is the ego car, and one step has no Python loop over
vehicles or episodes.

What is reproduced, rule by rule from highway-env 1.12 (constants are read from its classes,
not copied, so a changed constant there changes the twin too):

* the road: a straight road of ``lanes_count`` lanes, ``StraightLane.DEFAULT_WIDTH`` wide,
  speed limit 30 m/s; a vehicle's lane is the closest lane centre;
* initial placement (``Vehicle.create_random``): the ego car in a uniform lane at 25 m/s,
  then each other car in a uniform lane at U(0.7, 0.8) x the speed limit, each placed
  ``spacing * (12 + speed) * exp(-5/40 * lanes) * U(0.9, 1.1)`` metres ahead of the car
  before it; each other car draws its IDM exponent from ``IDMVehicle.DELTA_RANGE`` and starts
  its lane-change timer at ``(x + y) * pi mod LANE_CHANGE_DELAY``;
* the other cars' behaviour (``IDMVehicle.act``; ``traffic.py``): IDM acceleration on the car
  ahead in their lane (and in the target lane while changing), clipped to ``ACC_MAX``; MOBIL
  lane changes (politeness 0) every ``LANE_CHANGE_DELAY``; aborting a lane change when another
  car merging into the same lane is within the desired gap ahead; the cascaded lateral controller;
* the ego car (``MDPVehicle``): meta-actions LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER over
  the target speeds (20, 25, 30) m/s, applied once a decision, then the speed and steering
  controllers every frame;
* kinematics (``Vehicle.step``): the bicycle model, speed limited to +-40 m/s, 5 Hz frames,
  one decision a second, 30 s episodes;
* collisions (``RoadObject.handle_collisions``): only the ego car checks them (the fast
  variant switches them off for the others): the spherical pre-check, then the separating-axis
  test on the rotated rectangles with the one-frame sweep, "will intersect" pushing both cars
  apart and crashing them on the next frame, "intersecting" crashing them at once; a crashed
  car brakes to a stop with its wheels straight;
* the reward (``HighwayEnv._reward``, normalized, times on-road) and termination on a crash;
* our six features, computed from the 4 cars nearest along the road within 200 m, as the
  Kinematics observation with ``vehicles_count=5`` would show them.

Neighbour searches sort the cars by position once a frame and scan each lane's order
(``traffic.lane_neighbours``); the collision test is ego against each other car, O(vehicles).

Known differences, each with its reason:

* Random numbers, by default (``seeding="batch"``, for training): the same distributions,
  drawn in batches from one NumPy Generator, so a seed gives other traffic than highway-env's
  seed does (and a twin episode depends on how many episodes run beside it). With
  ``seeding="highway-env"`` (the single-episode env's default) episode i draws highway-env's
  own sequence from gymnasium's generator for seed + i, car after car, and so starts from the
  very scene highway-env builds for that seed; a reset then costs 0.6 ms instead of 3 us.
* Order within a frame: highway-env lets the cars act one after another, so a car's MOBIL
  choice can see the target lanes that cars before it in the list chose in the same frame.
  Here all cars decide on the state at the start of the frame.
* The abort test of a lane change looks only at the nearest car ahead that merges into the
  same lane, not at every such car.
* Exact ties in position (probability zero) may order differently.

Fidelity against highway-env is measured by ``python -m experiments.highway_fidelity`` and kept
by a test; moving a scene between the two simulators is ``scenes.py``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import numpy as np
from highway_env.envs.highway_env import HighwayEnvFast
from highway_env.road.lane import AbstractLane
from highway_env.vehicle.behavior import IDMVehicle

from .env import BASE_CONFIG, RANGE, SPEED_SCALE
from .geometry import (
    DIAGONAL, EGO_SPEED, IDM, KP_A, KP_HEADING, KP_LATERAL, LANE_WIDTH, LENGTH, MAX_SPEED, MAX_STEERING, MIN_SPEED,
    ROAD_LENGTH, TARGET_SPEEDS, RoadOrder, not_zero, separating_axes, wrap_to_pi)
from .traffic import Cars, idm, lane_changes, lane_neighbours

# highway-env's DiscreteMetaAction labels by index.
LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER = range(5)
OBSERVED = 4  # other cars in the Kinematics observation (vehicles_count 5 with the ego)
SEEDINGS = ("batch", "highway-env")


@dataclass(frozen=True)
class TwinConfig:
    """The scene's numbers, read from highway-env's config and classes (see ``from_highway_env``)."""

    lanes: int
    vehicles: int  # other cars
    duration: int  # decisions (seconds) per episode
    frames: int  # simulation frames per decision
    dt: float  # seconds per frame
    ego_spacing: float
    density: float
    speed_limit: float
    collision_reward: float
    right_lane_reward: float
    high_speed_reward: float
    reward_speed_range: tuple[float, float]
    perception: float  # metres: farther cars are not observed

    @classmethod
    def from_highway_env(cls, overrides: Optional[dict[str, Any]] = None) -> "TwinConfig":
        """The config ``gym.make("highway-fast-v0", config=BASE_CONFIG | overrides)`` runs with."""
        cfg = HighwayEnvFast.default_config()
        cfg.update({**BASE_CONFIG, **(overrides or {})})
        if cfg["simulation_frequency"] % cfg["policy_frequency"]:
            raise ValueError("simulation_frequency must be a multiple of policy_frequency")
        if not cfg["normalize_reward"] or cfg["lane_change_reward"] or cfg["offroad_terminal"]:
            raise ValueError("the twin implements the normalized reward without lane-change reward or "
                             "off-road termination")
        if IDMVehicle.POLITENESS:
            raise ValueError("the twin implements MOBIL with politeness 0, highway-env's IDMVehicle default")
        if cfg["controlled_vehicles"] != 1 or cfg["initial_lane_id"] is not None:
            raise ValueError("the twin implements one controlled car in a random lane")
        return cls(
            lanes=int(cfg["lanes_count"]), vehicles=int(cfg["vehicles_count"]),
            duration=int(cfg["duration"] * cfg["policy_frequency"]),
            frames=int(cfg["simulation_frequency"] // cfg["policy_frequency"]),
            dt=1 / cfg["simulation_frequency"],
            ego_spacing=float(cfg["ego_spacing"]), density=float(cfg["vehicles_density"]),
            speed_limit=30.0,  # HighwayEnv._create_road: straight_road_network(..., speed_limit=30)
            collision_reward=float(cfg["collision_reward"]), right_lane_reward=float(cfg["right_lane_reward"]),
            high_speed_reward=float(cfg["high_speed_reward"]),
            reward_speed_range=tuple(map(float, cfg["reward_speed_range"])),
            perception=float(HighwayEnvFast.PERCEPTION_DISTANCE),
        )


class HighwayTwin:
    """N highway episodes stepped together. State arrays have shape (envs, 1 + other cars).

    ``reset(mask)`` draws new scenes for the episodes in `mask`; ``step(actions)`` takes one
    highway-env meta-action index per episode and returns rewards, crashes and time-outs.
    ``features()`` gives our six features per episode. Finished episodes are not reset here:
    the vector env adapters decide when.
    """

    def __init__(self, num_envs: int, config: Optional[TwinConfig] = None, seed: Optional[int] = None,
                 seeding: str = "batch") -> None:
        if num_envs < 1:
            raise ValueError("num_envs must be at least 1")
        if seeding not in SEEDINGS:
            raise ValueError(f"seeding must be one of {', '.join(SEEDINGS)}, not {seeding!r}")
        self.config = config or TwinConfig.from_highway_env()
        self.num_envs = n = num_envs
        self.v = v = 1 + self.config.vehicles
        self.seeding = seeding
        self.x, self.y, self.heading, self.speed = (np.zeros((n, v)) for _ in range(4))
        self.target_speed, self.delta, self.timer = (np.zeros((n, v)) for _ in range(3))
        self.impact = np.zeros((n, v, 2))
        self.impact_pending = np.zeros((n, v), dtype=bool)
        self.crashed = np.zeros((n, v), dtype=bool)
        self.lane = np.zeros((n, v), dtype=np.int64)
        self.target_lane = np.zeros((n, v), dtype=np.int64)
        self.time = np.zeros(n, dtype=np.int64)
        self.seed(seed)
        self.reset(np.ones(n, dtype=bool))

    def seed(self, seed: Optional[int]) -> None:
        """"batch": one generator for all episodes. "highway-env": episode i gets
        highway-env's generator for seed + i (gymnasium's ``np_random``), kept across its resets
        as highway-env keeps its own."""
        self.rng = np.random.default_rng(seed)
        if self.seeding == "highway-env":
            base = seed if seed is not None else int(self.rng.integers(2**31))
            self.rngs = [np.random.Generator(np.random.PCG64(np.random.SeedSequence(base + i)))
                         for i in range(self.num_envs)]

    # ----- scenes -------------------------------------------------------------------------
    def _draw_batch(self, k: int) -> tuple[np.ndarray, ...]:
        """Lanes, speeds of the other cars, spacing factors and IDM exponents of k scenes, in
        batches from one generator (the same distributions as highway-env's draws)."""
        c, rng = self.config, self.rng
        lanes = rng.integers(0, c.lanes, size=(k, self.v))
        speeds = rng.uniform(0.7 * c.speed_limit, 0.8 * c.speed_limit, size=(k, self.v - 1))
        gap_factor = rng.uniform(0.9, 1.1, size=(k, self.v))
        deltas = rng.uniform(*IDM.DELTA_RANGE, size=(k, self.v))[:, 1:]  # a column for the ego too, unused
        return lanes, speeds, gap_factor, deltas

    def _draw_highway_env(self, episodes: np.ndarray) -> tuple[np.ndarray, ...]:
        """The same draws in highway-env's own order, car after car, from each episode's
        generator (HighwayEnv._create_vehicles, Vehicle.create_random, randomize_behavior), so
        the scene is the one highway-env builds from that generator. A loop over the episodes
        being reset and their cars: a reset, not a step."""
        c, k = self.config, len(episodes)
        lanes, gap_factor = np.zeros((k, self.v), dtype=np.int64), np.zeros((k, self.v))
        speeds, deltas = np.zeros((k, self.v - 1)), np.zeros((k, self.v - 1))
        for row, episode in enumerate(episodes):
            rng = self.rngs[episode]
            for car in range(self.v):
                rng.choice(["0"])  # the road's start node, as create_random draws it
                rng.choice(["1"])  # its end node
                lanes[row, car] = rng.choice(c.lanes)
                if car:
                    speeds[row, car - 1] = rng.uniform(0.7 * c.speed_limit, 0.8 * c.speed_limit)
                gap_factor[row, car] = rng.uniform(0.9, 1.1)
                if car:
                    deltas[row, car - 1] = rng.uniform(*IDM.DELTA_RANGE)
        return lanes, speeds, gap_factor, deltas

    def reset(self, mask: np.ndarray, repeat: int = 1) -> None:
        """New scenes for the episodes in `mask` (Vehicle.create_random, car after car).

        `repeat` > 1 (with every episode in `mask`): draw num_envs / repeat scenes, exactly as an
        env of that many episodes would from the same seed, and lay them out `repeat` times, block
        after block. The steps draw no random numbers, so block j replays block 0's episodes for
        whatever acts there: many policies meet the same traffic in one batch."""
        idx = np.flatnonzero(mask)
        k, c = len(idx), self.config
        if k == 0:
            return
        if repeat > 1 and (k != self.num_envs or k % repeat):
            raise ValueError(f"repeat={repeat} needs every one of the {self.num_envs} episodes reset, a multiple of it")
        drawn = idx[: k // repeat]
        lanes, other_speeds, gap_factor, deltas = (self._draw_highway_env(drawn) if self.seeding == "highway-env"
                                                   else self._draw_batch(len(drawn)))
        if repeat > 1:
            lanes, other_speeds, gap_factor, deltas = (np.tile(a, (repeat, 1)) for a in (lanes, other_speeds, gap_factor, deltas))
        speeds = np.concatenate([np.full((k, 1), EGO_SPEED), other_speeds], axis=1)
        spacing = np.concatenate([np.full((k, 1), c.ego_spacing), np.full((k, self.v - 1), 1 / c.density)], axis=1)
        offsets = spacing * (12 + speeds) * np.exp(-5 / 40 * c.lanes)
        gaps = offsets * gap_factor
        gaps[:, 0] += 3 * offsets[:, 0]  # the first car starts 3 offsets from the origin
        x = np.cumsum(gaps, axis=1)
        y = lanes * LANE_WIDTH
        self.x[idx], self.y[idx], self.speed[idx] = x, y, speeds
        self.heading[idx] = 0.0
        self.lane[idx] = lanes
        self.target_lane[idx] = lanes
        self.target_speed[idx] = speeds  # ControlledVehicle: target speed = initial speed (25 for the ego)
        self.delta[idx] = np.concatenate([np.full((k, 1), IDM.DELTA), deltas], axis=1)  # the ego's is unused
        self.timer[idx] = ((x + y) * np.pi) % IDM.LANE_CHANGE_DELAY
        self.impact[idx] = 0.0
        self.impact_pending[idx] = False
        self.crashed[idx] = False
        self.time[idx] = 0

    # ----- control and kinematics -------------------------------------------------------------
    def _steering(self) -> np.ndarray:
        """ControlledVehicle.steering_control towards each car's target lane (straight lanes)."""
        lateral = self.y - self.target_lane * LANE_WIDTH
        lateral_speed = -KP_LATERAL * lateral
        heading_command = np.arcsin(np.clip(lateral_speed / not_zero(self.speed), -1, 1))
        heading_ref = np.clip(heading_command, -np.pi / 4, np.pi / 4)
        heading_rate = KP_HEADING * wrap_to_pi(heading_ref - self.heading)
        slip = np.arcsin(np.clip(LENGTH / 2 / not_zero(self.speed) * heading_rate, -1, 1))
        return np.clip(np.arctan(2 * np.tan(slip)), -MAX_STEERING, MAX_STEERING)

    def _apply_meta_action(self, action: np.ndarray) -> None:
        """MDPVehicle.act / ControlledVehicle.act for the ego car's decision."""
        lanes = self.config.lanes
        faster, slower = action == FASTER, action == SLOWER
        if faster.any() or slower.any():
            span = TARGET_SPEEDS[-1] - TARGET_SPEEDS[0]
            index = np.clip(np.round((self.speed[:, 0] - TARGET_SPEEDS[0]) / span * (TARGET_SPEEDS.size - 1)),
                            0, TARGET_SPEEDS.size - 1).astype(np.int64)
            index = np.clip(index + faster.astype(np.int64) - slower.astype(np.int64), 0, TARGET_SPEEDS.size - 1)
            self.target_speed[:, 0] = np.where(faster | slower, TARGET_SPEEDS[index], self.target_speed[:, 0])
        step = np.where(action == LANE_LEFT, -1, np.where(action == LANE_RIGHT, 1, 0))
        lane = np.clip(self.target_lane[:, 0] + step, 0, lanes - 1)
        reachable = (np.abs(self.y[:, 0] - lane * LANE_WIDTH) <= 2 * LANE_WIDTH) & (self.x[:, 0] >= 0) \
            & (self.x[:, 0] < ROAD_LENGTH + AbstractLane.VEHICLE_LENGTH)
        self.target_lane[:, 0] = np.where((step != 0) & reachable, lane, self.target_lane[:, 0])

    def _frame(self, active: np.ndarray) -> None:
        """One simulation frame (Road.act, Road.step) for the episodes in `active`."""
        dt = self.config.dt
        order, cars = RoadOrder(self.x), Cars(self)
        front, rear = lane_neighbours(self, order)
        # follow[l]: each car's IDM acceleration behind the car ahead of it on lane l
        follow = np.stack([idm(cars, None, front[lane], self.delta) for lane in range(self.config.lanes)])
        saved = (self.target_lane.copy(), self.timer.copy())
        lane_changes(self, cars, order, follow, rear)
        # Frozen (finished) episodes keep their state.
        self.target_lane = np.where(active[:, None], self.target_lane, saved[0])
        self.timer = np.where(active[:, None], self.timer, saved[1])

        n, v = self.num_envs, self.v
        rows = np.arange(n)[:, None]
        me = np.broadcast_to(np.arange(v), (n, v))
        accel = follow[self.lane, rows, me]
        changing = self.lane != self.target_lane
        accel = np.where(changing, np.minimum(accel, follow[self.target_lane, rows, me]), accel)
        accel = np.clip(accel, -IDM.ACC_MAX, IDM.ACC_MAX)
        accel[:, 0] = KP_A * (self.target_speed[:, 0] - self.speed[:, 0])  # the ego's speed controller
        steering = self._steering()
        # Vehicle.clip_actions
        steering = np.where(self.crashed, 0.0, steering)
        accel = np.where(self.crashed, -self.speed, accel)
        accel = np.where(self.speed > MAX_SPEED, np.minimum(accel, MAX_SPEED - self.speed), accel)
        accel = np.where(self.speed < MIN_SPEED, np.maximum(accel, MIN_SPEED - self.speed), accel)

        # Vehicle.step (IDMVehicle.step advances its timer first)
        act = active[:, None]
        self.timer = np.where(act & (me > 0), self.timer + dt, self.timer)
        beta = np.arctan(0.5 * np.tan(steering))
        x = self.x + self.speed * np.cos(self.heading + beta) * dt
        y = self.y + self.speed * np.sin(self.heading + beta) * dt
        hit = self.impact_pending
        x, y = x + np.where(hit, self.impact[..., 0], 0.0), y + np.where(hit, self.impact[..., 1], 0.0)
        heading = self.heading + self.speed * np.sin(beta) / (LENGTH / 2) * dt
        speed = self.speed + accel * dt
        self.x, self.y = np.where(act, x, self.x), np.where(act, y, self.y)
        self.heading, self.speed = np.where(act, heading, self.heading), np.where(act, speed, self.speed)
        self.crashed |= hit & act
        self.impact_pending &= ~act
        lane_centres = np.arange(self.config.lanes) * LANE_WIDTH
        self.lane = np.argmin(np.abs(self.y[..., None] - lane_centres), axis=-1)
        self._collide(active, dt)

    def _collide(self, active: np.ndarray, dt: float) -> None:
        """RoadObject.handle_collisions(ego, other) for every other car, in list order.

        The spherical pre-check runs on all (episode, car) pairs; the separating-axis test only
        on the few pairs that pass it."""
        ego_x, ego_y, ego_speed = self.x[:, :1], self.y[:, :1], self.speed[:, :1]
        near = np.hypot(self.x[:, 1:] - ego_x, self.y[:, 1:] - ego_y) <= DIAGONAL + ego_speed * dt
        near &= active[:, None]
        if not near.any():
            return
        env, car = np.nonzero(near)
        car = car + 1
        intersecting, will, tx, ty = separating_axes(
            (self.x[env, 0], self.y[env, 0], self.heading[env, 0], self.speed[env, 0]),
            (self.x[env, car], self.y[env, car], self.heading[env, car], self.speed[env, car]), dt)
        # The ego's impact is set by the last car (in list order) that will hit it; np.nonzero
        # lists pairs in (episode, car) order, so the last assignment per episode wins.
        hit = np.flatnonzero(will)
        self.impact[env[hit], 0] = np.stack([tx[hit], ty[hit]], axis=1) / 2
        self.impact_pending[env[hit], 0] = True
        self.impact[env[hit], car[hit]] = -np.stack([tx[hit], ty[hit]], axis=1) / 2
        self.impact_pending[env[hit], car[hit]] = True
        crash = np.flatnonzero(intersecting)
        self.crashed[env[crash], 0] = True
        self.crashed[env[crash], car[crash]] = True

    # ----- the decision step --------------------------------------------------------------------
    def step(self, actions: np.ndarray, active: Optional[np.ndarray] = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One decision (highway-env meta-action index per episode) and its frames.

        Returns (reward, terminated, truncated) per episode. Episodes outside `active` stay as
        they are (reward 0)."""
        actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)
        active = np.ones(self.num_envs, dtype=bool) if active is None else np.asarray(active, dtype=bool)
        self.time = np.where(active, self.time + 1, self.time)
        saved_lane, saved_speed = self.target_lane[:, 0].copy(), self.target_speed[:, 0].copy()
        self._apply_meta_action(actions)
        self.target_lane[:, 0] = np.where(active, self.target_lane[:, 0], saved_lane)
        self.target_speed[:, 0] = np.where(active, self.target_speed[:, 0], saved_speed)
        for _ in range(self.config.frames):
            self._frame(active)
        reward = np.where(active, self.reward(), 0.0)
        terminated = self.crashed[:, 0].copy()
        truncated = self.time >= self.config.duration
        return reward, terminated, truncated

    def reward(self) -> np.ndarray:
        """HighwayEnv._reward: collision, right lane (by target lane), high forward speed,
        mapped to [0, 1], times on-road."""
        c = self.config
        forward = self.speed[:, 0] * np.cos(self.heading[:, 0])
        low, high = c.reward_speed_range
        speed_term = np.clip((forward - low) / (high - low), 0, 1)
        lane_term = self.target_lane[:, 0] / max(c.lanes - 1, 1)
        raw = c.collision_reward * self.crashed[:, 0] + c.right_lane_reward * lane_term + c.high_speed_reward * speed_term
        best = c.high_speed_reward + c.right_lane_reward
        normalized = (raw - c.collision_reward) / (best - c.collision_reward)
        on_road = (np.abs(self.y[:, 0] - self.lane[:, 0] * LANE_WIDTH) <= LANE_WIDTH / 2) \
            & (self.x[:, 0] >= -AbstractLane.VEHICLE_LENGTH) & (self.x[:, 0] < ROAD_LENGTH + AbstractLane.VEHICLE_LENGTH)
        return normalized * on_road

    def forward_speed(self) -> np.ndarray:
        return self.speed[:, 0] * np.cos(self.heading[:, 0])

    def features(self) -> np.ndarray:
        """Our six features per episode, (envs, 6) float32, as ``highway.kinematics_to_features``
        computes them from a Kinematics observation of the 4 cars nearest along the road."""
        c, n = self.config, self.num_envs
        ego_x, ego_y = self.x[:, :1], self.y[:, :1]
        dx = (self.x[:, 1:] - ego_x).astype(np.float32)
        dy = (self.y[:, 1:] - ego_y).astype(np.float32)
        seen = np.hypot(self.x[:, 1:] - ego_x, self.y[:, 1:] - ego_y) < c.perception
        key = np.where(seen, np.abs(self.x[:, 1:] - ego_x), np.inf)
        nearest = np.argsort(key, axis=1, kind="stable")[:, :OBSERVED]
        observed = np.take_along_axis(seen, nearest, axis=1)
        dx, dy = np.take_along_axis(dx, nearest, axis=1), np.take_along_axis(dy, nearest, axis=1)
        ego_y32 = ego_y.astype(np.float32)
        lane = np.clip(np.rint(ego_y32[:, 0] / LANE_WIDTH), 0, c.lanes - 1).astype(np.int64)
        other_lane = np.rint((ego_y32 + dy) / LANE_WIDTH).astype(np.int64)
        distance = np.where(observed, np.abs(dx), np.inf)

        def nearest_in(mask: np.ndarray) -> np.ndarray:
            return np.minimum(np.min(np.where(mask, distance, RANGE), axis=1), RANGE) / RANGE

        same = other_lane == lane[:, None]
        gap_ahead = nearest_in(same & (dx > 0))
        gap_behind = nearest_in(same & (dx <= 0))
        left = np.where(lane > 0, nearest_in(other_lane == (lane - 1)[:, None]), 0.0)
        right = np.where(lane < c.lanes - 1, nearest_in(other_lane == (lane + 1)[:, None]), 0.0)
        position = lane / (c.lanes - 1)
        vx = (self.speed[:, 0] * np.cos(self.heading[:, 0])).astype(np.float32)
        speed = np.clip(vx / SPEED_SCALE, 0.0, 1.0)
        out = np.stack([gap_ahead, gap_behind, left, right, position, speed], axis=1).astype(np.float32)
        assert out.shape == (n, 6)
        return out
