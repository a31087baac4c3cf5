"""The training environment of the paper's ACC-Based Controller, vectorised over environments.

Paper sidebar "Trajectory Simulator": a single-lane platoon where a real I-24 drive leads, the AV
follows it, and string-unstable IDM drivers follow the AV, so waves grow behind it unless the AV
damps them. Each of the `num_envs` environments runs one such platoon on a window of a training
drive; the state of all of them is one (environments x vehicles) array stepped together in numpy.
The building blocks are the simulator's own: the drive replay (`sim.drives`), the I-24 IDM
(`contract.idm`), the fuel model (`sim.energy`), the real planner in the loop (`sim.plans`
`SimulatedPlanner`, its plans aged as the agent ages them), for `accel` cars the agent's
`AccelLimiter` (range and jerk limits) between the bounded request and the car, and for `acc`
cars the stock ACC model driven by the agent's button sequencer
(`sim.emulator.acc.SimulatedAccCar`) behind the paper's clip (`clip_speed_setting`). The
observation and the decoding of the action are the car's own (`vehicle_agent.controllers.policy`),
so a trained policy meets on the car what it learnt on.

MDP (paper, "ACC-Based Controller"): observation and action as in `policy`; reward

    r_t = 1 - c1 a_t^2 - c2 (v_t - v_sp,t)^2 - c3 (1/n) sum_i E_t^i - c4 1[gap out of bounds]

with a_t the AV's acceleration, v_sp the plan's target at the AV, E^i the fuel rate (g/s) of the
AV and every vehicle behind it, and the gap bounds of `sim.gaps.GapBounds` (space gap within
[h_min, h_max] and time gap at least its minimum). An AV that touches its leader ends the
episode with `collision` taken once more for every step the episode had left (so crashing never
pays off against the gap penalty). The coefficients are in `RewardWeights`, with why.

Cut-ins (`EnvConfig.cut_ins`): drivers from the next lane merge into the AV's gap by the
evaluation simulator's rule (`sim.platoon.CutIns`), then drive as I-24 IDM humans ahead of it,
so the AV's leader is the nearest of them. Trained without them, a policy paid for a wide gap
only beyond h_max; in slow traffic a gap well inside 120 m invites cars (3 s beyond the 19 m a
merging car needs: 64 m at 15 m/s), and in `sim evaluate` such a policy let them in and fell
ever further behind its leader while its own gap stayed in bounds. Only the AV's gap invites
them here: the humans behind it keep the I-24 IDM's 1.24 s.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from contract.idm import I24_IDM, IdmParams, equilibrium_gap_m, idm_accel
from contract.units import MPS_PER_MPH, mps_to_mph
from planner import parse_params
from sim.av import PING_EVERY_STEPS, RADAR_RANGE_M
from sim.drives import Drive
from sim.emulator.acc import MIN_SET_SPEED_MPH, SimulatedAccCar, stock_acc_accel
from sim.energy import RAV4_2019
from sim.gaps import GapBounds
from sim.plans import SimulatedPlanner, simulated_grid, simulated_inrix
from sim.platoon import MAX_BRAKING_MPS2, MAX_SPACING_SPEED_SHARE, VEHICLE_LENGTH_M, CutIns
from sim.recorded import RecordedDrive
from sim.traffic import InrixFeed
from vehicle_agent.actuators import AccelLimiter
from vehicle_agent.controllers import clip_speed_setting
from vehicle_agent.controllers.acc_clip import CLIP_WINDOW_STEPS
from vehicle_agent.controllers.microaccel import LeadAccelEstimator
from vehicle_agent.controllers.policy import (
    ACCEL_ACTION_SIZES,
    ACCEL_OBSERVATION_SIZES,
    PLAN_LOOKAHEAD_M,
    AccelAction,
    AccelObservation,
    PolicyActuation,
    acc_features,
    accel_features,
    action_size,
    observation_size,
    requested_accel_mps2,
    requested_gap_setting,
    requested_speed_mph,
    requested_time_margin_s,
)
from vehicle_agent.controllers.rl_accel import SAFETY, bounded_request

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

# The planner setting of docs/simulation.md's evaluation (4 km window, plans up to 73 mph).
DEFAULT_PLANNER_PARAMS: Mapping[str, Any] = {
    "window_m": 4000.0,
    "speed_limit_allowance_mps": 1.34112,
}

# Room for the cars that merge ahead of the AV in one episode. While it is full no car merges
# (the merge clock waits): at the rate of `CutIns` a full room takes a policy that kept its gap
# seconds beyond the accepted one for most of the episode.
MAX_MERGED_CARS = 16


@dataclass(frozen=True)
class RewardWeights:
    """c1..c4 of the paper's reward, and the collision penalty per step left.

    Scaled so that each term costs about 0.1-0.3 of the per-step bonus 1 in its typical range,
    and none can be won by giving up another: c1 = 0.1 makes a 1 m/s^2 acceleration cost 0.1;
    c2 = 0.005 makes 5 m/s off the plan cost 0.125 (the plan is advice: holding it exactly is
    `simple`, and a wave-damping AV must be free to drive a little slower than a plan that is
    minutes old); c3 = 0.2 s/g makes the platoon's mean fuel at 30 m/s cruise (about 1.25 g/s,
    RAV4 fit) cost 0.25, so burning fuel in the waves behind the AV shows; c4 = 1 makes a step
    outside the gap bounds cost the whole bonus, the paper's intervention penalty.
    """

    accel: float = 0.1
    speed: float = 0.005
    fuel: float = 0.2
    gap: float = 1.0
    collision: float = 1.0


@dataclass(frozen=True)
class EnvConfig:
    """One training set-up: actuation (and how an `accel` action is read and what an `accel`
    policy observes), platoon, episode window, planner, reward, gap bounds."""

    actuation: PolicyActuation
    accel_action: AccelAction = "request"
    accel_observation: AccelObservation = "radar"
    humans: int = 10
    episode_s: float = 300.0
    planner: str = "kernel_smooth"
    planner_params: Mapping[str, Any] = field(default_factory=lambda: dict(DEFAULT_PLANNER_PARAMS))
    reward: RewardWeights = RewardWeights()
    gap_bounds: GapBounds = GapBounds()
    idm: IdmParams = I24_IDM
    # None trains without cut-ins, as every policy before 2026-12-03 22:30 UTC was.
    cut_ins: CutIns | None = CutIns()

    def __post_init__(self) -> None:
        if self.actuation not in ("acc", "accel"):
            raise ValueError(f"actuation {self.actuation!r} is not one of acc, accel")
        if self.accel_action not in ACCEL_ACTION_SIZES:
            raise ValueError(
                f"accel action {self.accel_action!r} is not one of {', '.join(ACCEL_ACTION_SIZES)}"
            )
        if self.actuation == "acc" and self.accel_action != "request":
            raise ValueError(
                f"the accel action {self.accel_action!r} is for accel policies, not acc"
            )
        if self.accel_observation not in ACCEL_OBSERVATION_SIZES:
            raise ValueError(
                f"accel observation {self.accel_observation!r} is not one of "
                f"{', '.join(ACCEL_OBSERVATION_SIZES)}"
            )
        if self.actuation == "acc" and self.accel_observation != "radar":
            raise ValueError(
                f"the accel observation {self.accel_observation!r} is for accel policies, not acc"
            )
        if self.humans < 1:
            raise ValueError(
                f"the platoon needs at least one human behind the AV, got {self.humans}"
            )
        if self.episode_s <= 0:
            raise ValueError(f"episode_s must be positive, got {self.episode_s}")


@dataclass
class _DriveRoad:
    """A training drive with what every episode on it shares (leader, road, and its INRIX: the
    recorded minutes of a recorded drive, else simulated once, when first needed)."""

    drive: Drive
    position_m: FloatArray
    feed: InrixFeed | None = None


class PlatoonVecEnv(gym.vector.VectorEnv[FloatArray, FloatArray, NDArray[Any]]):
    """`num_envs` platoons on training drives; actions and observations are batched rows.

    Finished environments reset within the same step (gymnasium's same-step autoreset): their
    last observation is in `infos["final_obs"]`, `infos["_final_obs"]` marks which rows.
    """

    metadata = {"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}

    def __init__(
        self,
        drives: Sequence[Drive],
        num_envs: int,
        config: EnvConfig,
        recorded: Sequence[RecordedDrive] = (),
    ) -> None:
        """Platoons behind `drives` (on simulated INRIX) and, beside them, behind `recorded`
        (each on its real INRIX minutes, as `sim evaluate`'s recorded scenarios drive)."""
        if not drives:
            raise ValueError("training needs at least one drive")
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        self.config = config
        self.num_envs = num_envs
        self.dt_s = drives[0].dt_s
        every = [*drives, *(one.drive for one in recorded)]
        if any(abs(drive.dt_s - self.dt_s) > 1e-9 for drive in every):
            raise ValueError("every training drive must have the same time step")
        self.episode_steps = int(round(config.episode_s / self.dt_s))
        roads = [_DriveRoad(drive, drive.position_m) for drive in drives]
        roads += [_DriveRoad(one.drive, one.drive.position_m, one.feed) for one in recorded]
        self.roads = [road for road in roads if road.drive.steps > self.episode_steps]
        if not self.roads:
            raise ValueError(f"no drive is longer than an episode ({config.episode_s:g} s)")
        self.planner_params = parse_params(config.planner_params)
        size = observation_size(config.actuation, config.accel_observation)
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, (size,), np.float64)
        self.action_size = action_size(config.actuation, config.accel_action)
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (self.action_size,), np.float64)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        vehicles = config.humans + 2  # leader, AV, humans
        self.position = np.zeros((num_envs, vehicles))
        self.speed = np.zeros((num_envs, vehicles))
        self.road_index = np.zeros(num_envs, dtype=np.int64)
        self.start_step = np.zeros(num_envs, dtype=np.int64)
        self.elapsed = np.zeros(num_envs, dtype=np.int64)
        self.target_here = np.zeros(num_envs)
        self.target_ahead = np.zeros(num_envs)
        # The cars that merged ahead of each AV, front to back (NaN: room for more), each
        # AV's integrated merge hazard and the exponential draw it must reach.
        self.merged_position = np.full((num_envs, MAX_MERGED_CARS), np.nan)
        self.merged_speed = np.full((num_envs, MAX_MERGED_CARS), np.nan)
        self.merged = np.zeros(num_envs, dtype=np.int64)
        self.merge_clock = np.zeros(num_envs)
        self.merge_threshold = np.zeros(num_envs)
        self.planners: list[SimulatedPlanner] = []
        self.cars: list[SimulatedAccCar] = []
        self.lead_accel = [LeadAccelEstimator(SAFETY.lead_accel_filter_s) for _ in range(num_envs)]
        self.limiters = [AccelLimiter() for _ in range(num_envs)]
        self.recent_mph: list[deque[float | None]] = [
            deque(maxlen=CLIP_WINDOW_STEPS) for _ in range(num_envs)
        ]
        self._rng = np.random.default_rng()
        # its own stream, so the windows drawn are the same with cut-ins as without
        self._merge_rng = np.random.default_rng()
        self.render_mode = None

    # -- episodes ---------------------------------------------------------------------------

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[FloatArray, dict[str, Any]]:
        """Start every environment on a random window of a random training drive."""
        if isinstance(seed, list):
            seed = seed[0] if seed else None
        if seed is not None:
            self._rng = np.random.default_rng(seed)
            self._merge_rng = np.random.default_rng([seed, 1])
        started = [self._start(env) for env in range(self.num_envs)]
        self.planners = [planner for planner, _ in started]
        self.cars = [car for _, car in started]
        self._lookup(range(self.num_envs))
        return self._features(), {}

    def _new_planner(self, road: int) -> SimulatedPlanner:
        entry = self.roads[road]
        if entry.feed is None:
            entry.feed = simulated_inrix(entry.drive, self.planner_params)
        return SimulatedPlanner(
            self.config.planner, self.planner_params, simulated_grid(entry.drive), entry.feed
        )

    def _start(self, env: int) -> tuple[SimulatedPlanner, SimulatedAccCar]:
        """Place environment `env`'s platoon on a new window; its new planner and ACC car."""
        road = int(self._rng.integers(len(self.roads)))
        entry = self.roads[road]
        first = int(self._rng.integers(entry.drive.steps - self.episode_steps))
        self.road_index[env] = road
        self.start_step[env] = first
        self.elapsed[env] = 0
        lead_speed = float(entry.drive.speed_mps[first])
        spacing_speed = min(lead_speed, MAX_SPACING_SPEED_SHARE * self.config.idm.desired_speed_mps)
        spacing = float(equilibrium_gap_m(self.config.idm, spacing_speed)) + VEHICLE_LENGTH_M
        vehicles = self.position.shape[1]
        self.position[env] = entry.position_m[first] - spacing * np.arange(vehicles)
        self.speed[env] = lead_speed
        self.merged_position[env] = np.nan
        self.merged_speed[env] = np.nan
        self.merged[env] = 0
        self.merge_clock[env] = 0.0
        if self.config.cut_ins is not None:
            self.merge_threshold[env] = self._merge_rng.exponential()
        car = SimulatedAccCar()
        car.acc.engage(max(lead_speed, MIN_SET_SPEED_MPH * MPS_PER_MPH))
        self.lead_accel[env].reset()
        # the agent takes over a car in equilibrium: its limiter starts from no acceleration
        self.limiters[env].reset(0.0, self._time_s(env))
        self.recent_mph[env].clear()
        return self._new_planner(road), car

    def _time_s(self, env: int) -> float:
        return float(self.start_step[env] + self.elapsed[env]) * self.dt_s

    def _av_leader(self) -> tuple[FloatArray, FloatArray]:
        """Each AV's leader's position and speed: the last car that merged ahead, else the
        drive's leader."""
        last = np.maximum(self.merged - 1, 0)
        rows = np.arange(self.num_envs)
        has_merged = self.merged > 0
        position = np.where(has_merged, self.merged_position[rows, last], self.position[:, 0])
        speed = np.where(has_merged, self.merged_speed[rows, last], self.speed[:, 0])
        return position, speed

    def _merge_cut_ins(self) -> BoolArray:
        """Cars from the next lane merge into the AV's gap (`sim.platoon.CutIns`, as
        `simulate_platoon` applies it): each in the middle of the gap at the mean of the AV's
        and its leader's speeds. Which environments had one merge."""
        cut_ins = self.config.cut_ins
        merging = np.zeros(self.num_envs, dtype=np.bool_)
        if cut_ins is None:
            return merging
        lead_position, lead_speed = self._av_leader()
        gap = lead_position - self.position[:, 1] - VEHICLE_LENGTH_M
        speed = self.speed[:, 1]
        if not cut_ins.invites_any(gap, speed):
            return merging
        room = self.merged < MAX_MERGED_CARS
        self.merge_clock += np.where(room, cut_ins.hazard_per_s(gap, speed), 0.0) * self.dt_s
        merging = room & (self.merge_clock >= self.merge_threshold)
        for env in np.flatnonzero(merging):
            slot = int(self.merged[env])
            self.merged_position[env, slot] = lead_position[env] - 0.5 * (
                gap[env] + VEHICLE_LENGTH_M
            )
            self.merged_speed[env, slot] = 0.5 * (lead_speed[env] + speed[env])
            self.merged[env] += 1
            self.merge_clock[env] = 0.0
            self.merge_threshold[env] = self._merge_rng.exponential()
        return merging

    def _move_merged_cars(self, dt: float) -> None:
        """The merged cars drive one step as I-24 IDM humans, each behind the car ahead of
        it (the first behind the drive's leader as the step starts)."""
        if not self.merged.any():
            return
        ahead_position = np.hstack([self.position[:, :1], self.merged_position[:, :-1]])
        ahead_speed = np.hstack([self.speed[:, :1], self.merged_speed[:, :-1]])
        speed = self.merged_speed
        with np.errstate(invalid="ignore"):  # the NaN of empty room stays NaN
            gap = ahead_position - self.merged_position - VEHICLE_LENGTH_M
            accel = idm_accel(self.config.idm, gap, speed, ahead_speed)
            accel = np.maximum(accel, -MAX_BRAKING_MPS2)
            accel = np.maximum(accel, -speed / dt)
            self.merged_position += speed * dt + 0.5 * accel * dt * dt
            self.merged_speed = np.maximum(speed + accel * dt, 0.0)

    # -- observation ------------------------------------------------------------------------

    def _lookup(self, rows: Iterable[int]) -> None:
        """The plan at each AV now (its pings go to its planner first, once a second)."""
        lead_position, _ = self._av_leader()
        for env in rows:
            time_s = self._time_s(env)
            x = float(self.position[env, 1])
            planner = self.planners[env]
            if self.elapsed[env] % PING_EVERY_STEPS == 0:
                gap = float(lead_position[env]) - x - VEHICLE_LENGTH_M
                planner.record_ping(
                    time_s,
                    x,
                    float(self.speed[env, 1]),
                    engaged=True,  # the policy drives every step of an episode
                    lead_present=gap <= RADAR_RANGE_M,
                )
            profile = planner.held_profile(time_s)
            self.target_here[env] = profile.at(x)
            self.target_ahead[env] = profile.at(x + PLAN_LOOKAHEAD_M)

    def _features(self) -> FloatArray:
        """Every AV's observation, as the car builds it."""
        speed = self.speed[:, 1]
        lead_position, lead_speed = self._av_leader()
        gap = lead_position - self.position[:, 1] - VEHICLE_LENGTH_M
        lead_present = gap <= RADAR_RANGE_M
        if self.config.actuation == "accel":
            commanded = None
            if self.config.accel_observation == "commanded_accel":
                commanded = np.array(
                    [limiter.reference_mps2 for limiter in self.limiters], dtype=np.float64
                )
            return accel_features(
                speed,
                self.target_here,
                self.target_ahead,
                lead_present,
                gap,
                lead_speed - speed,
                commanded,
            )
        setting = np.array([car.acc.set_speed_mph or 0.0 for car in self.cars], dtype=np.float64)
        bars = np.array([car.acc.gap_setting for car in self.cars], dtype=np.float64)
        return acc_features(speed, self.target_here, self.target_ahead, lead_present, setting, bars)

    # -- dynamics ---------------------------------------------------------------------------

    def _av_accel(self, actions: FloatArray, gap: FloatArray, lead_speed: FloatArray) -> FloatArray:
        """What each AV's car makes of the policy's action this step."""
        speed = self.speed[:, 1]
        if self.config.actuation == "accel":
            request = requested_accel_mps2(actions[:, 0])
            margin = (
                requested_time_margin_s(actions[:, 1])
                if self.config.accel_action == "request_time_margin"
                else np.zeros(self.num_envs)
            )
            accel = np.empty(self.num_envs)
            for env in range(self.num_envs):
                measured = bool(gap[env] <= RADAR_RANGE_M)
                rel = float(lead_speed[env] - speed[env])
                lead_accel = 0.0
                if measured:
                    lead_accel = self.lead_accel[env].update(
                        self._time_s(env), float(lead_speed[env]), float(gap[env])
                    )
                else:
                    self.lead_accel[env].reset()
                command = bounded_request(
                    float(request[env]),
                    float(speed[env]),
                    float(gap[env]) if measured else None,
                    rel if measured else None,
                    lead_accel,
                    float(margin[env]),
                )
                accel[env] = self.limiters[env].limit(
                    self._time_s(env), command, speed_mps=float(speed[env])
                )
            return accel
        # acc: v_action -> the paper's clip -> buttons (gap first) -> the stock ACC
        for env in range(self.num_envs):
            self.recent_mph[env].append(mps_to_mph(float(speed[env])))
        lead_present = gap <= RADAR_RANGE_M
        requested = requested_speed_mph(actions[:, 0], self.target_here / MPS_PER_MPH, lead_present)
        bars = requested_gap_setting(actions[:, 1])
        set_speed = np.empty(self.num_envs)
        time_gap = np.empty(self.num_envs)
        for env, car in enumerate(self.cars):
            final = clip_speed_setting(float(requested[env]), self.recent_mph[env])
            time_s = self._time_s(env)
            car.sequencer.request(final, int(bars[env]))
            held = car.sequencer.step(time_s, car.speed_setting_mph, car.gap_setting)
            car.acc.buttons(
                time_s, frozenset() if held is None else frozenset({held}), float(speed[env])
            )
            set_speed[env] = (car.acc.set_speed_mph or 0.0) * MPS_PER_MPH
            time_gap[env] = car.acc.params.time_gaps_s[car.acc.gap_setting - 1]
        return stock_acc_accel(
            speed,
            set_speed,
            time_gap,
            np.where(lead_present, gap, np.nan),
            np.where(lead_present, lead_speed, np.nan),
            self.cars[0].acc.params,
        )

    def step(
        self, actions: FloatArray
    ) -> tuple[FloatArray, FloatArray, BoolArray, BoolArray, dict[str, Any]]:
        """Every platoon moves one step (ballistic, synchronous); reward; same-step autoreset."""
        actions = np.asarray(actions, dtype=np.float64).reshape(self.num_envs, -1)
        if not np.all(np.isfinite(actions)):
            raise ValueError("the policy gave a non-finite action")
        weights = self.config.reward
        dt = self.dt_s
        merging_now = self._merge_cut_ins()
        lead_position, lead_speed = self._av_leader()
        gaps = self.position[:, :-1] - self.position[:, 1:] - VEHICLE_LENGTH_M
        gaps[:, 0] = lead_position - self.position[:, 1] - VEHICLE_LENGTH_M
        follower_speed = self.speed[:, 1:].copy()  # the speeds the step starts from
        # the AV's IDM acceleration is replaced below: only its gap reads its leader
        accel = idm_accel(self.config.idm, gaps, follower_speed, self.speed[:, :-1])
        av = self._av_accel(actions, gaps[:, 0], lead_speed)
        av = np.minimum(av, RAV4_2019.max_accel_mps2(follower_speed[:, 0]))
        accel[:, 0] = np.maximum(av, -MAX_BRAKING_MPS2)
        accel = np.maximum(accel, -follower_speed / dt)  # cars do not reverse
        self._move_merged_cars(dt)
        self.elapsed += 1
        lead_steps = self.start_step + self.elapsed
        for env in range(self.num_envs):
            road = self.roads[int(self.road_index[env])]
            self.position[env, 0] = road.position_m[lead_steps[env]]
            self.speed[env, 0] = road.drive.speed_mps[lead_steps[env]]
        self.position[:, 1:] += follower_speed * dt + 0.5 * accel * dt * dt
        self.speed[:, 1:] = np.maximum(follower_speed + accel * dt, 0.0)

        fuel = RAV4_2019.fuel_rate_gps(follower_speed, accel).mean(axis=1)
        av_gap = self._av_leader()[0] - self.position[:, 1] - VEHICLE_LENGTH_M
        bounds = self.config.gap_bounds
        outside = bounds.outside_space_bounds(av_gap) | bounds.under_time_gap(
            av_gap, self.speed[:, 1]
        )
        reward = (
            1.0
            - weights.accel * accel[:, 0] ** 2
            - weights.speed * (follower_speed[:, 0] - self.target_here) ** 2
            - weights.fuel * fuel
            - weights.gap * outside
        )
        collided = av_gap <= 0.0
        left = self.episode_steps - self.elapsed
        reward = np.where(collided, reward - weights.collision * left, reward)
        truncated = (self.elapsed >= self.episode_steps) & ~collided
        terminated = collided
        done = terminated | truncated
        infos: dict[str, Any] = {}
        self._lookup(range(self.num_envs))
        observation = self._features()
        if done.any():
            infos["final_obs"] = np.where(done[:, None], observation, 0.0)
            infos["_final_obs"] = done.copy()
            finished = [int(env) for env in np.flatnonzero(done)]
            for env in finished:
                self.planners[env], self.cars[env] = self._start(env)
            self._lookup(finished)
            observation = self._features()
        infos["fuel_gps"] = fuel
        infos["gap_outside"] = outside
        infos["cut_ins"] = merging_now
        return observation, reward, terminated, truncated, infos

    def close_extras(self, **kwargs: Any) -> None:
        """Nothing to release: the platoons are arrays."""
