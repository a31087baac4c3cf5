"""The platoon simulator of the paper's sidebar "Trajectory Simulator", vectorised over vehicles.

A leader replays a whole real I-24 drive; behind it drive the followers, in order: automated
vehicles (each run by an `AvPolicy`, e.g. the real vehicle-agent controller) and human drivers
(IDM with the I-24 parameters, string-unstable so waves grow along the platoon). All followers
react to the state at step k and move together to step k + 1 (synchronous update), with the
ballistic rule x += v dt + a dt^2 / 2, v += a dt.

Speeds never go below zero: a deceleration that would reverse a car within the step is reduced
to the one that stops it (cars do not drive backwards). Nothing else is bounded: a follower that
reaches its leader's bumper keeps going and the overlap is recorded as a collision, with every
gap below `gap_violation_m` recorded as a gap violation, so an unsafe controller shows up in the
results instead of being hidden by the simulator.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from contract.idm import I24_IDM, MIN_MODEL_GAP_M, IdmParams, equilibrium_gap_m
from sim.drives import Drive

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

# Bumper-to-bumper length of every simulated car (a midsize SUV is 4.6-4.9 m).
VEHICLE_LENGTH_M = 5.0
# Closer than this and not touching: no driver accepts it, so it is reported (not a collision).
GAP_VIOLATION_M = 1.0
# The hardest braking tyres give on dry asphalt (about 0.9 g); an AV command below is unphysical.
MAX_BRAKING_MPS2 = 9.0
# The followers start at the IDM equilibrium gap of the leader's first speed; at or above the
# IDM desired speed there is none, so the spacing uses at most this share of it.
MAX_SPACING_SPEED_SHARE = 0.98


@dataclass(frozen=True, slots=True)
class AvObservation:
    """What an automated vehicle senses at one step (its radar, its speedometer, its GPS)."""

    time_s: float
    position_m: float
    speed_mps: float
    gap_m: float
    lead_speed_mps: float


class AvPolicy(Protocol):
    """An automated vehicle's decision each step: its acceleration request in m/s^2."""

    def accel_mps2(self, observation: AvObservation) -> float:
        """The acceleration to apply over the next step."""
        ...


class SpeedLimit(Protocol):
    """A position-dependent speed limit (e.g. the bottleneck scenario's)."""

    def limits_mps(self, position_m: FloatArray) -> FloatArray | None:
        """Per-vehicle limit at these positions (inf where none), or None if none applies now."""
        ...


@dataclass(frozen=True)
class GapEvent:
    """A follower that touched its leader (collision) or came closer than the violation gap."""

    kind: str
    vehicle: int
    first_time_s: float
    min_gap_m: float


@dataclass(frozen=True)
class PlatoonRun:
    """Everything a run recorded: one row per time step, one column per vehicle (0 = leader)."""

    drive_name: str
    dt_s: float
    is_av: BoolArray
    position_m: FloatArray
    speed_mps: FloatArray
    vehicle_length_m: float
    gap_violation_m: float
    events: list[GapEvent] = field(default_factory=list)

    @property
    def time_s(self) -> FloatArray:
        """Time of each recorded row since the drive's start."""
        times: FloatArray = np.arange(self.position_m.shape[0], dtype=np.float64) * self.dt_s
        return times

    @property
    def accel_mps2(self) -> FloatArray:
        """Acceleration applied over each step (rows 0..T-1; the last row repeats T-1)."""
        diff = np.diff(self.speed_mps, axis=0) / self.dt_s
        accel: FloatArray = np.concatenate([diff, diff[-1:]], axis=0)
        return accel

    @property
    def gap_m(self) -> FloatArray:
        """Bumper-to-bumper gap of each follower to the vehicle ahead (columns 1..N-1)."""
        gaps: FloatArray = self.position_m[:, :-1] - self.position_m[:, 1:] - self.vehicle_length_m
        return gaps

    @property
    def collisions(self) -> int:
        """Followers that ever touched the vehicle ahead."""
        return sum(1 for event in self.events if event.kind == "collision")

    @property
    def gap_violations(self) -> int:
        """Followers that came closer than the violation gap without touching."""
        return sum(1 for event in self.events if event.kind == "gap_violation")


def platoon_roles(humans: int, avs: int = 1) -> BoolArray:
    """Follower roles (True = AV): AVs spread evenly, the first right behind the leader."""
    if humans < 0 or avs < 0 or humans + avs == 0:
        raise ValueError("a platoon needs at least one follower and no negative counts")
    followers = humans + avs
    roles = np.zeros(followers, dtype=bool)
    if avs:
        roles[np.floor(np.arange(avs) * followers / avs).astype(int)] = True
    return roles


def roles_for_penetration(followers: int, penetration: float) -> BoolArray:
    """Follower roles for a penetration rate (share of AVs, rounded, at least one if > 0)."""
    if not 0.0 <= penetration <= 1.0:
        raise ValueError(f"penetration must be between 0 and 1, got {penetration}")
    avs = round(followers * penetration)
    if penetration > 0:
        avs = max(avs, 1)
    return platoon_roles(followers - avs, avs)


def simulate_platoon(
    drive: Drive,
    roles: BoolArray,
    policies: Sequence[AvPolicy] = (),
    *,
    idm: IdmParams = I24_IDM,
    speed_limit: SpeedLimit | None = None,
    av_max_accel: Callable[[float], float] | None = None,
    vehicle_length_m: float = VEHICLE_LENGTH_M,
    gap_violation_m: float = GAP_VIOLATION_M,
) -> PlatoonRun:
    """Run a platoon behind the whole drive; `roles[i]` says whether follower i is an AV.

    `policies` holds one policy per AV, front to back. `av_max_accel(v)` bounds AV requests by
    what the powertrain can give (the energy model's feasible acceleration); requests below
    -MAX_BRAKING_MPS2 are unphysical and bounded there.
    """
    roles = np.asarray(roles, dtype=bool)
    av_columns = [int(i) + 1 for i in np.flatnonzero(roles)]
    if len(policies) != len(av_columns):
        raise ValueError(f"{len(av_columns)} AVs in the platoon but {len(policies)} policies")
    n = len(roles) + 1
    steps = drive.steps
    dt = drive.dt_s
    lead_position = drive.position_m
    lead_speed = drive.speed_mps

    position = np.empty((steps + 1, n))
    speed = np.empty((steps + 1, n))
    position[:, 0] = lead_position
    speed[:, 0] = lead_speed
    start_speed = float(lead_speed[0])
    spacing_speed = min(start_speed, MAX_SPACING_SPEED_SHARE * idm.desired_speed_mps)
    spacing = float(equilibrium_gap_m(idm, spacing_speed)) + vehicle_length_m
    position[0, 1:] = -spacing * np.arange(1, n)
    speed[0, 1:] = start_speed

    # IDM constants and work buffers, so the step allocates nothing.
    amax = idm.max_accel_mps2
    inv_v0 = 1.0 / idm.desired_speed_mps
    braking = 1.0 / (2.0 * math.sqrt(amax * idm.comfortable_decel_mps2))
    delta_is_four = idm.delta == 4.0
    followers = n - 1
    gap = np.empty(followers)
    approaching = np.empty(followers)
    desired = np.empty(followers)
    work = np.empty(followers)
    accel = np.empty(followers)
    half_dt2 = 0.5 * dt * dt
    av_pairs = list(zip(av_columns, policies, strict=True))
    stop_rate = -1.0 / dt

    for k in range(steps):
        x = position[k]
        v = speed[k]
        v_follow = v[1:]
        # gap s and approaching rate v - v_lead
        np.subtract(x[:-1], x[1:], out=gap)
        gap -= vehicle_length_m
        np.subtract(v_follow, v[:-1], out=approaching)
        # s* = s0 + v T + max(0, v dv) / (2 sqrt(ab))
        np.multiply(v_follow, approaching, out=desired)
        np.maximum(desired, 0.0, out=desired)
        desired *= braking
        np.multiply(v_follow, idm.time_gap_s, out=work)
        desired += work
        desired += idm.min_gap_m
        # (s*/s)^2 with the collision guard of contract.idm
        np.maximum(gap, MIN_MODEL_GAP_M, out=work)
        np.divide(desired, work, out=desired)
        np.multiply(desired, desired, out=desired)
        limits = speed_limit.limits_mps(x[1:]) if speed_limit is not None else None
        # (v/v0)^delta
        if limits is None:
            np.multiply(v_follow, inv_v0, out=work)
        else:
            np.divide(v_follow, np.minimum(limits, idm.desired_speed_mps), out=work)
        if delta_is_four:
            np.multiply(work, work, out=work)
            np.multiply(work, work, out=work)
        else:
            np.power(work, idm.delta, out=work)
        # a [1 - (v/v0)^delta - (s*/s)^2]
        np.add(work, desired, out=accel)
        np.subtract(1.0, accel, out=accel)
        accel *= amax
        for column, policy in av_pairs:
            own = float(v[column])
            request = policy.accel_mps2(
                AvObservation(
                    time_s=k * dt,
                    position_m=float(x[column]),
                    speed_mps=own,
                    gap_m=float(gap[column - 1]),
                    lead_speed_mps=float(v[column - 1]),
                )
            )
            if not math.isfinite(request):
                raise ValueError(f"AV {column} requested a non-finite acceleration {request}")
            if av_max_accel is not None:
                request = min(request, av_max_accel(own))
            if limits is not None and math.isfinite(limits[column - 1]):
                # The AV keeps the posted limit like every driver (IDM free-road term).
                request = min(request, amax * (1.0 - (own / float(limits[column - 1])) ** 4))
            accel[column - 1] = max(request, -MAX_BRAKING_MPS2)
        # never reverse: at most the deceleration that stops the car within the step
        np.multiply(v_follow, stop_rate, out=work)
        np.maximum(accel, work, out=accel)
        # ballistic update into the next row
        x_next = position[k + 1, 1:]
        np.multiply(v_follow, dt, out=x_next)
        np.multiply(accel, half_dt2, out=work)
        x_next += work
        x_next += x[1:]
        v_next = speed[k + 1, 1:]
        np.multiply(accel, dt, out=v_next)
        v_next += v_follow
        np.maximum(v_next, 0.0, out=v_next)  # v + (-v/dt) dt can round to -1e-16

    run = PlatoonRun(
        drive_name=drive.name,
        dt_s=dt,
        is_av=np.concatenate([[False], roles]),
        position_m=position,
        speed_mps=speed,
        vehicle_length_m=vehicle_length_m,
        gap_violation_m=gap_violation_m,
    )
    run.events.extend(gap_events(run.gap_m, dt, gap_violation_m))
    return run


def gap_events(gaps: FloatArray, dt_s: float, gap_violation_m: float) -> list[GapEvent]:
    """One event per follower whose gap ever reached 0 (collision) or fell below the limit."""
    events: list[GapEvent] = []
    smallest = gaps.min(axis=0)
    for follower in np.flatnonzero(smallest < gap_violation_m):
        column = gaps[:, follower]
        collided = column <= 0.0
        kind = "collision" if collided.any() else "gap_violation"
        first = int(np.argmax(collided if collided.any() else column < gap_violation_m))
        events.append(
            GapEvent(
                kind=kind,
                vehicle=int(follower) + 1,
                first_time_s=first * dt_s,
                min_gap_m=float(smallest[follower]),
            )
        )
    return events
