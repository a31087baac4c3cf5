"""A multi-lane hour of corridor traffic, every vehicle, as I-24 MOTION would record it.

Each lane is a stream of drivers following the Intelligent Driver Model (`sim.idm`, the field
team's string-unstable I-24 human driver), entering the section's upstream end at a demand rate
and leaving at its downstream end. Downstream of the section the traffic moves at a real drive's
speed (`boundary_speed_mps`, e.g. a stop-and-go drive of ../shared/data/trajectories): a vehicle
past the end relaxes towards that speed, so the real drive's slowdowns enter the section from
downstream and, the IDM being string-unstable, grow into waves travelling upstream, as on I-24.
Vehicles keep their lane (MOTION fragments do change lanes; the Edie fields need only positions).

The step is 0.04 s, MOTION's 25 Hz, with the ballistic update of `sim.platoon`
(x += v dt + a dt^2 / 2, v += a dt, never below zero). Positions are recorded while a vehicle is
inside the section, so a trajectory is what the testbed's cameras would see; those still inside
when the run ends are cut there, like MOTION's fragments at the edge of a published window.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from contract.idm import I24_IDM, IdmParams, idm_accel
from contract.units import METRES_PER_FOOT
from sim.drives import Drive

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

MOTION_STEP_S = 0.04  # I-24 MOTION publishes 25 positions a second
# MOTION's coarse vehicle classes, their share of I-24 traffic (a guess from the paper's class
# list, not a measured mix) and their length, width and height in feet.
VEHICLE_CLASSES: dict[int, tuple[str, float, tuple[float, float, float]]] = {
    0: ("sedan", 0.42, (15.5, 6.0, 4.8)),
    1: ("midsize", 0.30, (16.0, 6.2, 5.6)),
    2: ("van", 0.05, (17.0, 6.6, 6.5)),
    3: ("pickup", 0.13, (19.5, 6.7, 6.2)),
    4: ("semi", 0.08, (70.0, 8.5, 13.5)),
    5: ("truck", 0.02, (30.0, 8.0, 11.0)),
}
FLEET_CLASS = 1  # the fleet's RAV4s, Rogues and XT5s are midsize SUVs
# Past the section's end a vehicle approaches the downstream speed with this time constant,
# within comfortable limits (the IDM's b and a), never faster than the IDM would allow.
BOUNDARY_RELAXATION_S = 2.0
# A vehicle this far past the section's end no longer holds anyone up and is dropped.
DROP_AFTER_END_M = 1500.0
# New vehicles enter no closer than their IDM safe gap s0 + v T behind the lane's last vehicle.
ENTRY_SPEED_MPS = 25.0
# Trajectories are gathered every this many steps (one minute of 25 Hz steps).
FLUSH_EVERY_STEPS = 1500


def _positive(value: float) -> bool:
    """A finite number above 0."""
    return math.isfinite(value) and value > 0


@dataclass(frozen=True, slots=True)
class MotionRunConfig:
    """What to simulate: the section on the corridor, its lanes and the demand."""

    start_unix_s: float
    duration_s: float = 3600.0
    section_start_m: float = 0.0
    section_length_m: float = 6437.4  # the testbed's four miles
    lanes: int = 4
    demand_veh_per_h_per_lane: float = 1500.0
    fleet_share: float = 0.02
    seed: int = 0
    driver: IdmParams = I24_IDM

    def __post_init__(self) -> None:
        # NaN and infinity too: `x <= 0` let them through
        if not (_positive(self.duration_s) and _positive(self.section_length_m)):
            raise ValueError(
                "duration_s and section_length_m must be finite and above 0, not "
                f"{self.duration_s} and {self.section_length_m}"
            )
        if self.lanes < 1:
            raise ValueError(f"lanes must be at least 1, not {self.lanes}")
        if not _positive(self.demand_veh_per_h_per_lane):
            raise ValueError(
                "demand_veh_per_h_per_lane must be finite and above 0, not "
                f"{self.demand_veh_per_h_per_lane}"
            )
        if not 0.0 <= self.fleet_share <= 1.0:
            raise ValueError(f"fleet_share must be within [0, 1], not {self.fleet_share}")


@dataclass(frozen=True, slots=True)
class SimulatedTrajectory:
    """One vehicle's positions inside the section, every 0.04 s from `first_unix_s`."""

    vehicle_index: int
    first_unix_s: float
    x_m: FloatArray
    lane: int
    vehicle_class: int
    length_ft: float
    width_ft: float
    height_ft: float
    is_fleet: bool

    @property
    def timestamps(self) -> FloatArray:
        """Unix time of each position."""
        times: FloatArray = self.first_unix_s + MOTION_STEP_S * np.arange(
            len(self.x_m), dtype=np.float64
        )
        return times


@dataclass
class _Road:
    """The vehicles entered so far (arrays indexed by vehicle, grown as they enter)."""

    capacity: int
    x_m: FloatArray = field(init=False)
    speed_mps: FloatArray = field(init=False)
    leader: IntArray = field(init=False)
    lane: IntArray = field(init=False)
    length_m: FloatArray = field(init=False)
    count: int = 0

    def __post_init__(self) -> None:
        self.x_m = np.zeros(self.capacity)
        self.speed_mps = np.zeros(self.capacity)
        self.leader = np.full(self.capacity, -1, dtype=np.int64)
        self.lane = np.zeros(self.capacity, dtype=np.int64)
        self.length_m = np.zeros(self.capacity)


def simulate_motion_run(
    config: MotionRunConfig, boundary_speed_mps: FloatArray
) -> Iterator[SimulatedTrajectory]:
    """Every vehicle's trajectory through the section, yielded as each one leaves it.

    `boundary_speed_mps` is the downstream traffic speed every 0.04 s (held at its last value
    if shorter than the run). Memory holds only the vehicles inside the section.
    """
    boundary = np.asarray(boundary_speed_mps, dtype=np.float64)
    if boundary.ndim != 1 or len(boundary) == 0 or not np.all(np.isfinite(boundary)):
        raise ValueError("boundary_speed_mps must be a non-empty series of finite speeds")
    if np.any(boundary < 0):
        raise ValueError("boundary_speed_mps must not be negative")
    rng = np.random.default_rng(config.seed)
    driver = config.driver
    steps = int(round(config.duration_s / MOTION_STEP_S))
    start, end = config.section_start_m, config.section_start_m + config.section_length_m
    expected = config.demand_veh_per_h_per_lane * config.lanes * config.duration_s / 3600.0
    road = _Road(capacity=int(expected * 1.3) + 64)
    codes = np.array(list(VEHICLE_CLASSES))
    shares = np.array([share for _, share, _ in VEHICLE_CLASSES.values()])
    shares = shares / shares.sum()
    vehicle_class = np.zeros(road.capacity, dtype=np.int64)
    is_fleet = np.zeros(road.capacity, dtype=bool)
    first_step = np.zeros(road.capacity, dtype=np.int64)
    # Poisson arrivals per lane; an arrival that cannot enter yet waits (a point queue).
    mean_headway_s = 3600.0 / config.demand_veh_per_h_per_lane
    next_arrival_s = rng.exponential(mean_headway_s, config.lanes)
    last_in_lane = np.full(config.lanes, -1, dtype=np.int64)
    alive = np.zeros(0, dtype=np.int64)
    is_alive = np.zeros(road.capacity, dtype=bool)
    pending: dict[int, list[FloatArray]] = {}
    chunk_ids: list[IntArray] = []
    chunk_x: list[FloatArray] = []
    finished: list[int] = []
    for step in range(steps):
        now_s = step * MOTION_STEP_S
        for lane in range(config.lanes):
            if next_arrival_s[lane] > now_s or road.count >= road.capacity:
                continue
            ahead = int(last_in_lane[lane])
            entry_speed = ENTRY_SPEED_MPS
            if ahead >= 0:
                entry_speed = min(entry_speed, float(road.speed_mps[ahead]))
                room = road.x_m[ahead] - road.length_m[ahead] - start
                if room < driver.min_gap_m + entry_speed * driver.time_gap_s:
                    continue
            index = road.count
            road.count += 1
            code = int(rng.choice(codes, p=shares))
            fleet = bool(rng.random() < config.fleet_share)
            if fleet:
                code = FLEET_CLASS
            vehicle_class[index] = code
            is_fleet[index] = fleet
            road.x_m[index] = start
            road.speed_mps[index] = entry_speed
            road.leader[index] = ahead
            road.lane[index] = lane + 1
            road.length_m[index] = VEHICLE_CLASSES[code][2][0] * METRES_PER_FOOT
            first_step[index] = step
            last_in_lane[lane] = index
            alive = np.append(alive, index)
            is_alive[index] = True
            next_arrival_s[lane] += rng.exponential(mean_headway_s)
        x = road.x_m[alive]
        v = road.speed_mps[alive]
        leaders = road.leader[alive]
        lead_index = np.maximum(leaders, 0)
        has_leader = (leaders >= 0) & is_alive[lead_index]
        gap = np.where(has_leader, road.x_m[lead_index] - road.length_m[lead_index] - x, np.inf)
        lead_speed = np.where(has_leader, road.speed_mps[lead_index], v)
        accel = idm_accel(driver, gap, v, lead_speed)
        downstream = boundary[min(step, len(boundary) - 1)]
        relax = np.clip(
            (downstream - v) / BOUNDARY_RELAXATION_S,
            -driver.comfortable_decel_mps2,
            driver.max_accel_mps2,
        )
        accel = np.where(x >= end, np.minimum(accel, relax), accel)
        accel = np.maximum(accel, -v / MOTION_STEP_S)  # stop, never reverse
        road.x_m[alive] = x + v * MOTION_STEP_S + 0.5 * accel * MOTION_STEP_S**2
        road.speed_mps[alive] = np.maximum(v + accel * MOTION_STEP_S, 0.0)
        inside = x < end
        chunk_ids.append(alive[inside])
        chunk_x.append(x[inside])
        leaving = alive[(x < end) & (road.x_m[alive] >= end)]
        finished.extend(int(i) for i in leaving)
        dropped = road.x_m[alive] >= end + DROP_AFTER_END_M
        is_alive[alive[dropped]] = False
        alive = alive[~dropped]
        if (step + 1) % FLUSH_EVERY_STEPS == 0 or step == steps - 1:
            _gather(pending, chunk_ids, chunk_x)
            chunk_ids.clear()
            chunk_x.clear()
            if step == steps - 1:
                finished.extend(i for i in pending if i not in set(finished))
            for index in finished:
                parts = pending.pop(index, None)
                if not parts:
                    continue
                length_ft, width_ft, height_ft = VEHICLE_CLASSES[int(vehicle_class[index])][2]
                yield SimulatedTrajectory(
                    vehicle_index=index,
                    first_unix_s=config.start_unix_s + int(first_step[index]) * MOTION_STEP_S,
                    x_m=np.concatenate(parts),
                    lane=int(road.lane[index]),
                    vehicle_class=int(vehicle_class[index]),
                    length_ft=length_ft,
                    width_ft=width_ft,
                    height_ft=height_ft,
                    is_fleet=bool(is_fleet[index]),
                )
            finished.clear()


def _gather(
    pending: dict[int, list[FloatArray]], chunk_ids: list[IntArray], chunk_x: list[FloatArray]
) -> None:
    """Append a chunk of (vehicle, position) steps to each vehicle's list, in time order."""
    if not chunk_ids:
        return
    ids = np.concatenate(chunk_ids)
    xs = np.concatenate(chunk_x)
    order = np.argsort(ids, kind="stable")
    ids, xs = ids[order], xs[order]
    cuts = np.flatnonzero(np.diff(ids)) + 1
    for vehicle_ids, positions in zip(np.split(ids, cuts), np.split(xs, cuts), strict=True):
        if len(vehicle_ids):
            pending.setdefault(int(vehicle_ids[0]), []).append(positions)


def boundary_speeds(drives: list[Drive], duration_s: float) -> FloatArray:
    """Downstream speed every 0.04 s for `duration_s`: the drives' speeds one after another.

    The drives are replayed in turn (and again from the first if they are shorter than the run),
    each resampled from its own step to MOTION's by linear interpolation.
    """
    if not drives:
        raise ValueError("boundary_speeds needs at least one drive")
    if not _positive(duration_s):
        raise ValueError(f"duration_s must be finite and above 0, not {duration_s}")
    pieces: list[FloatArray] = []
    covered = 0.0
    while covered < duration_s:
        for drive in drives:
            original = drive.dt_s * np.arange(len(drive.speed_mps))
            resampled = np.arange(0.0, drive.duration_s, MOTION_STEP_S)
            pieces.append(np.interp(resampled, original, drive.speed_mps))
            covered += drive.duration_s
            if covered >= duration_s:
                break
    steps = int(round(duration_s / MOTION_STEP_S))
    result: FloatArray = np.concatenate(pieces)[:steps]
    return result
