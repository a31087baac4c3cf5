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
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from contract.idm import I24_IDM, MIN_MODEL_GAP_M, IdmParams, equilibrium_gap_m
from sim.drives import Drive
from vehicle_agent.controllers.microaccel import LeadAccelEstimator
from vehicle_agent.stopping import (
    LEAD_ACCEL_FILTER_S,
    STOCK_ACC_MAX_BRAKING_MPS2,
    STOP_NEED_RELEASE_SHARE,
    required_braking_mps2,
)

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.intp]

# Bumper-to-bumper length of every simulated car (a midsize SUV is 4.6-4.9 m).
VEHICLE_LENGTH_M = 5.0
# Closer than this and not touching: no driver accepts it, so it is reported (not a collision).
GAP_VIOLATION_M = 1.0
# The hardest braking tyres give on dry asphalt (about 0.9 g); an AV command below is unphysical.
MAX_BRAKING_MPS2 = 9.0
# Columns for cars merging in are made this many at a time, so a cut-in copies the run's arrays
# only once per block instead of on every merge (the copy was a third of a run's time).
CUT_IN_BLOCK = 32
# The followers start at the IDM equilibrium gap of the leader's first speed; at or above the
# IDM desired speed there is none, so the spacing uses at most this share of it.
MAX_SPACING_SPEED_SHARE = 0.98


class AvObservation(NamedTuple):
    """What an automated vehicle senses at one step (its radar, its speedometer, its GPS).

    A named tuple, immutable as a frozen dataclass is but built in half the time: the
    simulator builds one per AV and step, and a frozen dataclass's `object.__setattr__` per
    field cost 1 us more of a step of about 55."""

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
    """A follower that touched its leader (collision) or came closer than the violation gap.
    `vehicle` numbers the platoon's columns 1..N-1, then the cars that merged in, N on."""

    kind: str
    vehicle: int
    first_time_s: float
    min_gap_m: float


def _with_merged_cars(own: FloatArray, merged: FloatArray | None) -> FloatArray:
    """The platoon's own columns, then those of the cars that merged in (if any did)."""
    if merged is None or not merged.shape[1]:
        return own
    return np.hstack([own, merged])


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
    # Gap of each follower to whatever vehicle is ahead of it (a cut-in included); None: the
    # platoon's own order throughout (columns 1..N-1 behind 0..N-2).
    follower_gap_m: FloatArray | None = None
    # Speed of the vehicle ahead of each follower at each step (the car it follows, a cut-in
    # included); None: the platoon's own order throughout.
    follower_lead_speed_mps: FloatArray | None = None
    # Cars that merged in from the next lane: NaN before they did. Their gaps to the car ahead
    # and its speed count in the safety KPIs, like every follower's; fuel, speed and comfort are
    # the platoon's own.
    cut_in_position_m: FloatArray | None = None
    cut_in_speed_mps: FloatArray | None = None
    cut_in_gap_m: FloatArray | None = None
    cut_in_lead_speed_mps: FloatArray | None = None
    # Hand-backs of the AVs to their drivers, and the seconds the drivers then drove.
    takeovers: int = 0
    driver_seconds: float = 0.0

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
        if self.follower_gap_m is not None:
            return self.follower_gap_m
        gaps: FloatArray = self.position_m[:, :-1] - self.position_m[:, 1:] - self.vehicle_length_m
        return gaps

    @property
    def lead_speed_mps(self) -> FloatArray:
        """Speed of the vehicle ahead of each follower (columns 1..N-1), paired with `gap_m`."""
        if self.follower_lead_speed_mps is not None:
            return self.follower_lead_speed_mps
        ahead: FloatArray = self.speed_mps[:, :-1]
        return ahead

    @property
    def every_gap_m(self) -> FloatArray:
        """`gap_m`, then each car that merged in (NaN before it did): every gap someone drove."""
        return _with_merged_cars(self.gap_m, self.cut_in_gap_m)

    @property
    def every_follower_speed_mps(self) -> FloatArray:
        """Speed of the vehicle behind each gap of `every_gap_m`."""
        return _with_merged_cars(self.speed_mps[:, 1:], self.cut_in_speed_mps)

    @property
    def every_lead_speed_mps(self) -> FloatArray:
        """Speed of the vehicle ahead of each gap of `every_gap_m`."""
        return _with_merged_cars(self.lead_speed_mps, self.cut_in_lead_speed_mps)

    @property
    def cut_ins(self) -> int:
        """Cars that merged into the platoon from the next lane."""
        return 0 if self.cut_in_position_m is None else int(self.cut_in_position_m.shape[1])

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


@dataclass(frozen=True)
class HandBack:
    """What happens when an AV's stop needs more braking than its actuation has.

    The need is judged on the radar's gap and leader speed (`vehicle_agent.stopping`): on a
    RAV4 the agent reads them and hands the car back at once; on a button car (Rogue, XT5) the
    agent cannot, and the same rule stands for the car's own forward-collision warning, which
    reads that radar. Either way the driver then needs `reaction_time_s` to brake: 1.25 s,
    Green's (2000, "How long does it take to stop?") brake reaction to an unexpected but common
    signal, for an attentive test driver alerted by the warning. Meanwhile the car's stock ACC
    drives (a RAV4's resumes when the agent stops requesting; a button car's was driving all
    along), braking at most `STOCK_ACC_MAX_BRAKING_MPS2`: the I-24 IDM's acceleration bounded
    below there. Then the driver drives: the IDM human, braking as hard as the stop needs up to
    the tyres' limit (`MAX_BRAKING_MPS2`). The agent takes over again once the stop
    need has stayed below `release_share` of its authority (the agent's own hysteresis,
    `vehicle_agent.stopping.STOP_NEED_RELEASE_SHARE`) for `reengage_after_s`: the agent's
    own override hold-off (3 s after the driver's last touch) plus its engage delay (1 s),
    `vehicle_agent.engage.EngagePolicy`. Every hand-back is a takeover in the KPIs. Not
    modelled: the agent also takes over no `accel` car above 75 mph
    (`EngageInputs.within_commandable_speed`): an engaged car stays so over the top, so it can
    bind only when an `accel` AV faster than that is taken over after driving on its own, here
    or once a plan is fresh (`sim.av`) (docs/simulation.md, the hand-back row).

    The radar sees a leader within `radar_range_m`: the paper's "minicar" flag is nominally
    80-100 m (Table 2); the RAV4's radar reported leaders up to 113-250 m on 27 of the 32 shared
    drives (`SpaceGap` below its 252 m "none" value). 100 m is the conservative common range.
    """

    radar_range_m: float = 100.0
    release_share: float = STOP_NEED_RELEASE_SHARE
    reengage_after_s: float = 4.0
    reaction_time_s: float = 1.25

    def __post_init__(self) -> None:
        if not 0.0 <= self.reaction_time_s < self.reengage_after_s:
            raise ValueError(
                f"reaction time {self.reaction_time_s} s must be >= 0 and shorter than the "
                f"{self.reengage_after_s} s before the agent takes over again"
            )


@dataclass(frozen=True)
class CutIns:
    """Vehicles from the next lane merging into a large gap ahead of a follower.

    Rule (for every driver, AV or human, so the all-human baseline meets it too): the room a
    merging car needs, `min_gap_m` (a 5 m car with 7 m on each side), does not invite it; the
    rest of the gap, in seconds at the follower's speed, does once it exceeds
    `accept_time_gap_s` (3.0 s: half again the widest gap a stock ACC leaves, its 3-bar ~2.0 s,
    paper "ACC-Based Controller", and 2.4 times the I-24 human's 1.24 s). A driver in the next
    lane then merges in at a Poisson rate of `rate_per_s_per_s` per second of that time gap
    beyond the threshold (at 25 m/s: none below 94 m, one merge per 10 s on average at 119 m).
    The merging car takes the middle of the gap at the mean of the follower's and its leader's
    speeds and then drives as an I-24 IDM human. Cut-ins are frequent even at stock gaps (AAA's
    2024 road test of driver-assistance systems: one cut-in every 24.4 minutes of ACC driving,
    the most common event needing the driver); the rate beyond the threshold is our
    assumption, seeded and configurable, so its effect can be bracketed (0 turns it off). The
    field team bounded the AV's gap at 120 m in training for the same reason.
    Cut-in cars count in throughput where they cross a measurement point in this lane (a gap
    they fill is not lost to the road); fuel, speed and comfort stay over the platoon's own
    vehicles, whose braking for the merging cars is the cost of the gap.
    """

    accept_time_gap_s: float = 3.0
    rate_per_s_per_s: float = 0.1
    min_gap_m: float = 19.0
    seed: int = 0

    def invites_any(self, gap_m: FloatArray, speed_mps: FloatArray) -> bool:
        """False when no gap has room beyond the accepted time gap, so every hazard is 0 (a
        cheap test first: on most steps no driver is left room)."""
        return bool((gap_m - self.min_gap_m > self.accept_time_gap_s * speed_mps).any())

    def hazard_per_s(self, gap_m: FloatArray, speed_mps: FloatArray) -> FloatArray:
        """The merge rate into each gap now (one per follower)."""
        moving = (speed_mps >= MIN_CUT_IN_SPEED_MPS) & (gap_m >= self.min_gap_m)
        spare = gap_m - self.min_gap_m
        excess = np.divide(spare, speed_mps, out=np.zeros_like(gap_m), where=moving)
        excess -= self.accept_time_gap_s
        hazard: FloatArray = self.rate_per_s_per_s * np.where(moving, np.maximum(excess, 0.0), 0.0)
        return hazard


# Nobody changes lanes into a gap of a queue that stands still (m/s).
MIN_CUT_IN_SPEED_MPS = 1.0


@runtime_checkable
class SupervisedPolicy(AvPolicy, Protocol):
    """An AV policy that can be handed back to its driver (what `HandBack` needs)."""

    @property
    def braking_authority_mps2(self) -> float:
        """The hardest braking (positive) the policy's actuation makes."""
        ...

    def driver_drives(self, observation: AvObservation) -> None:
        """The driver drives this step: keep reporting, forget the controller's state."""
        ...


@dataclass
class _AvState:
    """One AV's supervision and cut-in clocks."""

    column: int
    policy: AvPolicy
    engaged: bool = True
    calm_since_s: float | None = None
    handed_back_s: float = -math.inf
    # The leader's braking as the radar's successive speeds show it (as the agent estimates it).
    lead_accel: LeadAccelEstimator = field(
        default_factory=lambda: LeadAccelEstimator(LEAD_ACCEL_FILTER_S)
    )


def simulate_platoon(
    drive: Drive,
    roles: BoolArray,
    policies: Sequence[AvPolicy] = (),
    *,
    idm: IdmParams = I24_IDM,
    speed_limit: SpeedLimit | None = None,
    av_max_accel: Callable[[float], float] | None = None,
    hand_back: HandBack | None = None,
    cut_ins: CutIns | None = None,
    vehicle_length_m: float = VEHICLE_LENGTH_M,
    gap_violation_m: float = GAP_VIOLATION_M,
) -> PlatoonRun:
    """Run a platoon behind the whole drive; `roles[i]` says whether follower i is an AV.

    `policies` holds one policy per AV, front to back. `av_max_accel(v)` bounds AV requests by
    what the powertrain can give (the energy model's feasible acceleration); requests below
    -MAX_BRAKING_MPS2 are unphysical and bounded there. With `hand_back`, every AV is supervised
    as the agent supervises itself (policies must be `SupervisedPolicy`); with `cut_ins`,
    drivers from the next lane merge into large gaps ahead of AVs. Without them the simulator
    applies the requests as they come, so an unsafe policy shows up as collisions.
    """
    roles = np.asarray(roles, dtype=bool)
    av_columns = [int(i) + 1 for i in np.flatnonzero(roles)]
    if len(policies) != len(av_columns):
        raise ValueError(f"{len(av_columns)} AVs in the platoon but {len(policies)} policies")
    if hand_back is not None:
        for policy in policies:
            if not isinstance(policy, SupervisedPolicy):
                raise ValueError(f"{type(policy).__name__} cannot be handed back to a driver")
    n = len(roles) + 1
    steps = drive.steps
    dt = drive.dt_s

    position = np.full((steps + 1, n), np.nan)
    speed = np.full((steps + 1, n), np.nan)
    position[:, 0] = drive.position_m
    speed[:, 0] = drive.speed_mps
    start_speed = float(drive.speed_mps[0])
    spacing_speed = min(start_speed, MAX_SPACING_SPEED_SHARE * idm.desired_speed_mps)
    spacing = float(equilibrium_gap_m(idm, spacing_speed)) + vehicle_length_m
    position[0, 1:] = -spacing * np.arange(1, n)
    speed[0, 1:] = start_speed
    # The vehicle ahead of each column (the leader's entry is unused): the platoon's order
    # until a cut-in slips a car in ahead of an AV.
    lead_of = np.arange(-1, n - 1)
    gap_history = np.full((steps + 1, n), np.nan)
    lead_speed_history = np.full((steps + 1, n), np.nan)

    # IDM constants and work buffers, so a step allocates nothing (until a cut-in adds a car).
    amax = idm.max_accel_mps2
    inv_v0 = 1.0 / idm.desired_speed_mps
    braking = 1.0 / (2.0 * math.sqrt(amax * idm.comfortable_decel_mps2))
    delta_is_four = idm.delta == 4.0
    half_dt2 = 0.5 * dt * dt
    stop_rate = -1.0 / dt
    # The same constants as operands of the step's numpy calls (`_operand`).
    max_accel_operand = _operand(amax)
    inv_v0_operand = _operand(inv_v0)
    braking_operand = _operand(braking)
    time_gap_operand = _operand(idm.time_gap_s)
    min_gap_operand = _operand(idm.min_gap_m)
    desired_speed_operand = _operand(idm.desired_speed_mps)
    delta_operand = _operand(idm.delta)
    half_dt2_operand = _operand(half_dt2)
    stop_rate_operand = _operand(stop_rate)
    dt_operand = _operand(dt)
    length_operand = _operand(vehicle_length_m)
    min_model_gap_operand = _operand(MIN_MODEL_GAP_M)
    max_braking_operand = _operand(-MAX_BRAKING_MPS2)
    zero = _operand(0.0)
    one = _operand(1.0)
    rng = np.random.default_rng([cut_ins.seed, zlib.crc32(drive.name.encode())] if cut_ins else 0)
    avs = [_AvState(column, policy) for column, policy in zip(av_columns, policies, strict=True)]
    # Each follower's integrated merge hazard, and the exponential draw it must reach.
    merge_clock = np.zeros(n)
    merge_threshold = rng.exponential(size=n)
    takeovers = 0
    driver_steps = 0
    # Every column from 1 on follows someone: cut-in cars take the next free column and follow
    # from the step they merge (NaN before, which no arithmetic below reads); `used` columns
    # hold cars, the rest is room for the next ones.
    used = n
    in_order = True
    buffers = np.empty((4, n - 1))

    for k in range(steps):
        x = position[k, :used]
        v = speed[k, :used]
        # the gaps and lead speeds are computed into this step's rows of their histories
        gap = gap_history[k, 1:used]
        v_lead = lead_speed_history[k, 1:used]
        _gaps_into(gap, v_lead, x, v, lead_of, in_order, length_operand)
        # without room anywhere no clock moves, so none can reach its draw this step
        if cut_ins is not None and cut_ins.invites_any(gap, v[1:]):
            merge_clock[1:] += cut_ins.hazard_per_s(gap, v[1:]) * dt
            merging = np.flatnonzero(merge_clock >= merge_threshold)
            for follower in merging:
                ahead = int(lead_of[follower])
                gap_now = float(x[ahead] - x[follower]) - vehicle_length_m
                merge_clock[follower] = 0.0
                merge_threshold[follower] = rng.exponential()
                if used == position.shape[1]:
                    room = np.full((steps + 1, CUT_IN_BLOCK), np.nan)
                    position = np.hstack([position, room])
                    speed = np.hstack([speed, room])
                    gap_history = np.hstack([gap_history, room])
                    lead_speed_history = np.hstack([lead_speed_history, room])
                new = used
                used += 1
                position[k, new] = float(x[ahead]) - 0.5 * (gap_now + vehicle_length_m)
                speed[k, new] = 0.5 * float(v[ahead] + v[follower])
                lead_of = np.append(lead_of, ahead)
                lead_of[follower] = new
                merge_clock = np.append(merge_clock, 0.0)
                merge_threshold = np.append(merge_threshold, rng.exponential())
                in_order = False
                buffers = np.empty((4, new))
                x = position[k, :used]
                v = speed[k, :used]
            if merging.size:
                gap = gap_history[k, 1:used]
                v_lead = lead_speed_history[k, 1:used]
                _gaps_into(gap, v_lead, x, v, lead_of, in_order, length_operand)
        desired, work, accel, limits_work = buffers
        v_follow = v[1:]
        # s* = s0 + v T + max(0, v dv) / (2 sqrt(ab))
        np.subtract(v_follow, v_lead, out=desired)
        desired *= v_follow
        np.maximum(desired, zero, out=desired)
        desired *= braking_operand
        np.multiply(v_follow, time_gap_operand, out=work)
        desired += work
        desired += min_gap_operand
        # (s*/s)^2 with the collision guard of contract.idm
        np.maximum(gap, min_model_gap_operand, out=work)
        np.divide(desired, work, out=desired)
        np.multiply(desired, desired, out=desired)
        limits = speed_limit.limits_mps(x[1:]) if speed_limit is not None else None
        # (v/v0)^delta
        if limits is None:
            np.multiply(v_follow, inv_v0_operand, out=work)
        else:
            np.minimum(limits, desired_speed_operand, out=limits_work)
            np.divide(v_follow, limits_work, out=work)
        if delta_is_four:
            np.multiply(work, work, out=work)
            np.multiply(work, work, out=work)
        else:
            np.power(work, delta_operand, out=work)
        # a [1 - (v/v0)^delta - (s*/s)^2]
        np.add(work, desired, out=accel)
        np.subtract(one, accel, out=accel)
        accel *= max_accel_operand
        for av in avs:
            i = av.column - 1
            own = float(v_follow[i])
            observation = AvObservation(
                time_s=k * dt,
                position_m=float(x[av.column]),
                speed_mps=own,
                gap_m=float(gap[i]),
                lead_speed_mps=float(v_lead[i]),
            )
            if hand_back is not None:
                was_engaged = av.engaged
                _supervise(av, observation, hand_back)
                if was_engaged and not av.engaged:
                    takeovers += 1
                if not av.engaged:
                    driver_steps += 1
                    av.policy.driver_drives(observation)  # type: ignore[attr-defined]
                    if observation.time_s - av.handed_back_s < hand_back.reaction_time_s:
                        # the driver has not yet reacted: the stock ACC brakes what it may
                        accel[i] = max(accel[i], -STOCK_ACC_MAX_BRAKING_MPS2)
                    continue  # the driver: the IDM acceleration already in `accel`
            request = av.policy.accel_mps2(observation)
            if not math.isfinite(request):
                raise ValueError(f"AV {av.column} requested a non-finite acceleration {request}")
            if av_max_accel is not None:
                request = min(request, av_max_accel(own))
            if limits is not None and math.isfinite(limits[i]):
                # The AV keeps the posted limit like every driver (IDM free-road term).
                request = min(request, amax * (1.0 - (own / float(limits[i])) ** idm.delta))
            accel[i] = request
        # no harder than the tyres give, and never reverse within the step
        np.maximum(accel, max_braking_operand, out=accel)
        np.multiply(v_follow, stop_rate_operand, out=work)
        np.maximum(accel, work, out=accel)
        # ballistic update into the next row (NaN columns of cars not yet merged stay NaN)
        x_next = position[k + 1, 1:used]
        np.multiply(v_follow, dt_operand, out=x_next)
        np.multiply(accel, half_dt2_operand, out=work)
        x_next += work
        x_next += x[1:]
        v_next = speed[k + 1, 1:used]
        np.multiply(accel, dt_operand, out=v_next)
        v_next += v_follow
        np.maximum(v_next, zero, out=v_next)  # v + (-v/dt) dt can round to -1e-16
    last = position[steps, :used]
    gap_history[steps, 1:used] = last[lead_of[1:]] - last[1:] - vehicle_length_m
    lead_speed_history[steps, 1:used] = speed[steps, lead_of[1:]]

    run = PlatoonRun(
        drive_name=drive.name,
        dt_s=dt,
        is_av=np.concatenate([[False], roles]),
        position_m=position[:, :n],
        speed_mps=speed[:, :n],
        vehicle_length_m=vehicle_length_m,
        gap_violation_m=gap_violation_m,
        follower_gap_m=gap_history[:, 1:n],
        follower_lead_speed_mps=lead_speed_history[:, 1:n],
        cut_in_position_m=position[:, n:used],
        cut_in_speed_mps=speed[:, n:used],
        cut_in_gap_m=gap_history[:, n:used],
        cut_in_lead_speed_mps=lead_speed_history[:, n:used],
        takeovers=takeovers,
        driver_seconds=driver_steps * dt,
    )
    run.events.extend(gap_events(run.every_gap_m, dt, gap_violation_m))
    return run


def _operand(value: float) -> FloatArray:
    """`value` as a 0-d float64 array, for a numpy call of the step: numpy 2 converts a Python
    float operand afresh on every call (about 0.4 us, as long as the operation on 200 cars
    takes), and takes a 0-d array as it is. It holds the same float64, so every result is the
    same to the bit."""
    return np.array(value, dtype=np.float64)


def _gaps_into(
    gap: FloatArray,
    lead_speed: FloatArray,
    position: FloatArray,
    speed: FloatArray,
    lead_of: IntArray,
    in_order: bool,
    vehicle_length_m: FloatArray,
) -> None:
    """Each follower's bumper-to-bumper gap and its leader's speed, into the step's buffers
    (plain slices while the platoon keeps its order, the cheap case of every step without a
    cut-in)."""
    if in_order:
        np.subtract(position[:-1], position[1:], out=gap)
        lead_speed[:] = speed[:-1]
    else:
        ahead_of = lead_of[1:]
        np.subtract(position[ahead_of], position[1:], out=gap)
        np.take(speed, ahead_of, out=lead_speed)
    gap -= vehicle_length_m


def _supervise(av: _AvState, observation: AvObservation, hand_back: HandBack) -> None:
    """The agent's stopping check on what its radar sees; hand back, or take over again."""
    policy = av.policy
    authority = policy.braking_authority_mps2  # type: ignore[attr-defined]
    if observation.gap_m <= hand_back.radar_range_m:
        need = required_braking_mps2(
            observation.speed_mps,
            observation.gap_m,
            observation.lead_speed_mps,
            av.lead_accel.update(observation.time_s, observation.lead_speed_mps, observation.gap_m),
        )
    else:
        av.lead_accel.reset()
        need = 0.0
    if av.engaged:
        if need > authority:
            av.engaged = False
            av.calm_since_s = None
            av.handed_back_s = observation.time_s
        return
    if need > hand_back.release_share * authority:
        av.calm_since_s = None
        return
    if av.calm_since_s is None:
        av.calm_since_s = observation.time_s
    if observation.time_s - av.calm_since_s >= hand_back.reengage_after_s:
        av.engaged = True


def gap_events(gaps: FloatArray, dt_s: float, gap_violation_m: float) -> list[GapEvent]:
    """One event per follower whose gap ever reached 0 (collision) or fell below the limit
    (a column is NaN where its car was not yet in the lane)."""
    events: list[GapEvent] = []
    smallest = np.nanmin(gaps, axis=0)
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
