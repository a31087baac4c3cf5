"""The fuel-optimal AV trajectory with full knowledge of the leader: the bound every controller's
saving is a share of (paper sidebar "Optimized Vehicle Trajectory", problem (S4) with its
envelope (S5)).

The platoon is the evaluation's: the replayed leader, one AV right behind it, then the I-24 IDM
humans, starting at the IDM equilibrium spacing, stepped exactly as `sim.platoon` steps it (dt of
the drive, ballistic update, no reversing, the AV's request capped by the RAV4's feasible
acceleration). The objective is the platoon's fuel per distance over every vehicle, the leader
included, from the RAV4 model (the paper's sidebar used the L2 norm of the accelerations as a
proxy). That is not quite the evaluation's fuel KPI, which leaves the leader out
(`sim.kpi.platoon_kpis`), and the saving reported is that KPI's, measured on the replay: the
leader's fuel and distance are fixed by the drive (1 vehicle of 26), but they are in the ratio
optimised, so the bound is the optimum of this objective read in the KPI, not the KPI's own optimum
(by how much the two differ is not measured). Per distance, not total fuel: over a fixed horizon,
total fuel rewards the whole platoon for driving less far, which the envelope allows (up to h_max
behind the leader) and which is no saving. Per distance alone still rewards driving slower (the RAV4
burns least per metre near 14 m/s) and ending the drive slower (the fuel model's P(v) a term credits
the kinetic energy given up), so the platoon must also end the drive having driven as far as the
all-human platoon did (no distance lost, summed over the followers), every follower at least as fast
as it was: with these, a constant-speed leader's optimum is to cruise, as Jensen's inequality on the
convex fuel-per-distance curve says.

The AV's acceleration is piecewise constant over `control_interval_s` and bounded by the accel
controllers' limits (MicroAccel: -3 to 1.5 m/s^2); the gap envelope of `sim.gaps.GapBounds`
(space gap within [h_min, h_max], time gap at least 1 s) is a quadratic penalty of growing
weight, optimised against bounds tightened by a margin so that what is left of the penalty stays
inside the real bounds.

As the sidebar does, the gradient comes from the adjoint of the discrete dynamics, derived by
hand below and compiled with numba (one forward and one backward sweep over the drive, about
the cost of two simulations), and L-BFGS-B (scipy) does the descent under the box bounds.
The returned trajectory is then replayed in the real simulator (`simulate_platoon` with
`ReplayPolicy`), and every figure reported comes from that replay.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from contract.controllers import MicroAccelParams
from contract.idm import I24_IDM, MIN_MODEL_GAP_M, IdmParams
from sim.drives import Drive
from sim.energy import RAV4_2019, FuelModel
from sim.gaps import GapBounds, gap_kpis
from sim.kpi import fuel_saving_pct, platoon_kpis
from sim.platoon import (
    MAX_BRAKING_MPS2,
    AvObservation,
    PlatoonRun,
    platoon_roles,
    simulate_platoon,
)

FloatArray = NDArray[np.float64]

# The humans behind the AV in the evaluation's platoon.
HUMANS = 24
# L-BFGS-B's status when its line search fails, its steps per line search (scipy's default 20
# is short for the fuel model's kinks), and the least decrease (g) worth a restart.
ABNORMAL_LINE_SEARCH = 2
LINE_SEARCH_STEPS = 50
IMPROVEMENT_G = 1e-3
_MICROACCEL = MicroAccelParams()


@dataclass(frozen=True, slots=True)
class OptimumSettings:
    """How the optimal control problem is discretised and solved."""

    # Length of each piece of the piecewise-constant control (the paper's parameterisation).
    control_interval_s: float = 1.0
    # The accel controllers' command range (MicroAccel defaults).
    min_accel_mps2: float = _MICROACCEL.min_accel_mps2
    max_accel_mps2: float = _MICROACCEL.max_accel_mps2
    # Penalty weights (g per m^2 s of violation), raised in turn; each stage warm-starts the next.
    penalty_weights: tuple[float, ...] = (1.0, 10.0, 100.0, 1000.0)
    # The envelope is tightened by this much inside the optimiser (m, and s of time gap).
    margin_m: float = 0.5
    margin_s: float = 0.05
    # L-BFGS-B iterations per penalty stage.
    max_iterations: int = 400
    # Where the descent starts. 0: the AV driving as the humans do (the all-human run). Above
    # 0: the AV driving the leader's speed averaged over this many seconds centred on each
    # moment, a smoother start in another basin of this non-convex problem (a second start
    # whose better result is the tighter bound).
    start_smoothing_s: float = 0.0

    def __post_init__(self) -> None:
        if self.control_interval_s <= 0:
            raise ValueError(f"control_interval_s must be positive, got {self.control_interval_s}")
        if not self.min_accel_mps2 < 0.0 < self.max_accel_mps2:
            raise ValueError(
                f"min_accel_mps2 < 0 < max_accel_mps2 is needed (cruising must be possible), got "
                f"[{self.min_accel_mps2}, {self.max_accel_mps2}] m/s^2"
            )
        if not self.penalty_weights or min(self.penalty_weights) <= 0:
            raise ValueError(f"penalty_weights must be positive, got {self.penalty_weights}")
        if self.margin_m < 0 or self.margin_s < 0:
            raise ValueError(f"margin_m and margin_s must not be negative, got {self.margin_m}")
        if self.max_iterations < 1:
            raise ValueError(f"max_iterations must be at least 1, got {self.max_iterations}")
        if not self.start_smoothing_s >= 0:
            raise ValueError(
                f"start_smoothing_s must not be negative, got {self.start_smoothing_s}"
            )


@dataclass(frozen=True)
class OptimumResult:
    """The optimal AV accelerations of one drive and what their replay in the simulator did."""

    drive_name: str
    # The AV's acceleration request over each simulator step (length = drive.steps).
    accel_mps2: FloatArray
    # Platoon fuel (every vehicle, the leader included) of the replay and of the all-human run.
    fuel_g: float
    baseline_fuel_g: float
    # The evaluation's fuel saving (per distance, over the KPIs' vehicles: sim.kpi), and
    # 1 - fuel / all-human fuel over every vehicle, the leader included, in %.
    fuel_saving_pct: float
    total_fuel_saving_pct: float
    max_gap_m: float
    min_gap_m: float
    gap_out_of_bounds_s: float
    time_gap_violation_s: float
    collisions: int
    iterations: int
    seconds: float
    # Where the descent started (`OptimumSettings.start_smoothing_s`; 0: the all-human run).
    start_smoothing_s: float
    run: PlatoonRun


class ReplayPolicy:
    """An AV policy that plays back a fixed acceleration per simulator step."""

    def __init__(self, accel_mps2: FloatArray, dt_s: float) -> None:
        self._accel = np.asarray(accel_mps2, dtype=np.float64)
        self._dt_s = dt_s

    def accel_mps2(self, observation: AvObservation) -> float:
        """The recorded acceleration of this step."""
        return float(self._accel[int(round(observation.time_s / self._dt_s))])


def platoon_fuel_g(run: PlatoonRun, model: FuelModel = RAV4_2019) -> float:
    """Total fuel of every vehicle of a run (leader included), f(v_k, a_k) dt summed (paper eq.)."""
    accel = np.diff(run.speed_mps, axis=0) / run.dt_s
    return float(model.fuel_rate_gps(run.speed_mps[:-1], accel).sum() * run.dt_s)


def _distance_m(run: PlatoonRun) -> float:
    """Distance driven by every vehicle of a run, the leader included."""
    return float((run.position_m[-1] - run.position_m[0]).sum())


def _fuel_coefficients(model: FuelModel) -> FloatArray:
    return np.array(
        [
            model.c0,
            model.c1,
            model.c2,
            model.c3,
            model.p0,
            model.p1,
            model.p2,
            model.q0,
            model.q1,
            model.beta,
            model.fuel_cut_speed_mps,
            model.b1,
            model.b2,
            model.b3,
        ]
    )


def _idm_coefficients(idm: IdmParams) -> FloatArray:
    return np.array(
        [
            idm.max_accel_mps2,
            idm.comfortable_decel_mps2,
            idm.delta,
            idm.min_gap_m,
            idm.desired_speed_mps,
            idm.time_gap_s,
        ]
    )


def _envelope(bounds: GapBounds, settings: OptimumSettings) -> FloatArray:
    return np.array(
        [
            bounds.min_gap_m + settings.margin_m,
            bounds.max_gap_m - settings.margin_m,
            bounds.min_time_gap_s + settings.margin_s,
        ]
    )


def _platoon_cost_gradient_py(
    request: FloatArray,
    lead_x: FloatArray,
    lead_v: FloatArray,
    start_x: FloatArray,
    start_v: FloatArray,
    idm: FloatArray,
    fuel: FloatArray,
    envelope: FloatArray,
    dt: float,
    length: float,
    others: FloatArray,
    weight: float,
    gradient: FloatArray,
) -> tuple[float, float]:
    """Platoon fuel per distance and envelope penalty of the AV's requests; gradient in place.

    The fuel term is (F + F_other) / (D + D_other) * D_ref in grams: F, D the followers' fuel
    and distance, `others` = [F_other, D_other, D_ref, X_end, v_end...] (the leader's fuel and
    distance, the all-human platoon's distance that scales the ratio back to grams, the sum of
    the followers' end positions and each follower's end speed not to fall short of: the
    metres short per follower and each m/s short are penalised, squared).
    Follower 0 is the AV, 1.. the IDM humans. The forward sweep is `simulate_platoon`'s step;
    the backward sweep is its adjoint (reverse-mode derivative of every operation, the clips
    included: a clipped quantity passes no gradient through the clipped argument).
    """
    steps = request.shape[0]
    n = start_x.shape[0]
    amax, bcomf, delta, s0, v0, tgap = idm[0], idm[1], idm[2], idm[3], idm[4], idm[5]
    c0, c1, c2, c3 = fuel[0], fuel[1], fuel[2], fuel[3]
    p0, p1, p2, q0, q1 = fuel[4], fuel[5], fuel[6], fuel[7], fuel[8]
    beta, cut_speed, b1, b2, b3 = fuel[9], fuel[10], fuel[11], fuel[12], fuel[13]
    low, high, min_time_gap = envelope[0], envelope[1], envelope[2]
    braking = 1.0 / (2.0 * math.sqrt(amax * bcomf))
    half_dt2 = 0.5 * dt * dt
    x = np.empty((steps + 1, n))
    v = np.empty((steps + 1, n))
    a = np.empty((steps, n))
    x[0] = start_x
    v[0] = start_v
    fuel_g = 0.0
    penalty = 0.0
    # forward: simulate_platoon's step
    for k in range(steps):
        for i in range(n):
            own_v = v[k, i]
            if i == 0:
                cap = b1 * math.exp(-b2 * own_v) + b3
                acc = min(request[k], cap)
                acc = max(acc, -MAX_BRAKING_MPS2)
            else:
                gap = x[k, i - 1] - x[k, i] - length
                desired = s0 + own_v * tgap + max(0.0, own_v * (own_v - v[k, i - 1])) * braking
                ratio = desired / max(gap, MIN_MODEL_GAP_M)
                free = own_v / v0
                # pow() dominates the sweep; the I-24 IDM's delta is 4
                free = free * free * free * free if delta == 4.0 else free**delta
                acc = amax * (1.0 - free - ratio * ratio)
            acc = max(acc, -own_v / dt)
            a[k, i] = acc
            x[k + 1, i] = x[k, i] + own_v * dt + acc * half_dt2
            v[k + 1, i] = max(own_v + acc * dt, 0.0)
            a_plus = max(acc, 0.0)
            rate = (
                c0
                + own_v * (c1 + own_v * (c2 + own_v * c3))
                + (p0 + own_v * (p1 + own_v * p2)) * acc
                + (q0 + q1 * own_v) * a_plus * a_plus
            )
            floor = beta if own_v <= cut_speed else 0.0
            fuel_g += max(rate, floor) * dt
    # envelope penalty on the AV's gap at every state after the first
    for k in range(1, steps + 1):
        gap = lead_x[k] - x[k, 0] - length
        penalty += (
            max(low - gap, 0.0) ** 2
            + max(gap - high, 0.0) ** 2
            + max(min_time_gap * v[k, 0] - gap, 0.0) ** 2
        ) * dt
    # per follower, so the weight means the same as the envelope's (metres squared)
    shortfall = others[3]
    for i in range(n):
        shortfall -= x[steps, i]
    shortfall = max(shortfall, 0.0) / n
    penalty += shortfall * shortfall
    for i in range(n):
        penalty += max(others[4 + i] - v[steps, i], 0.0) ** 2
    # fuel per distance, scaled to grams: d/dF = D_ref / D, d/dx_final = -F D_ref / D^2
    total_fuel = fuel_g + others[0]
    distance = others[1]
    for i in range(n):
        distance += x[steps, i] - x[0, i]
    scale = others[2] / distance
    # backward: adj_x, adj_v hold the adjoint of state k; the penalty of state k joins it
    # first, then it is carried back through step k - 1
    adj_x = np.full(n, -total_fuel * scale / distance)
    adj_v = np.zeros(n)
    for i in range(n):
        adj_x[i] -= weight * 2.0 * shortfall / n
        adj_v[i] = -weight * 2.0 * max(others[4 + i] - v[steps, i], 0.0)
    new_x = np.zeros(n)
    new_v = np.zeros(n)
    for k in range(steps, 0, -1):
        gap = lead_x[k] - x[k, 0] - length
        excess = max(min_time_gap * v[k, 0] - gap, 0.0)
        d_gap = 2.0 * (max(gap - high, 0.0) - max(low - gap, 0.0) - excess)
        adj_x[0] -= weight * dt * d_gap
        adj_v[0] += weight * dt * 2.0 * excess * min_time_gap
        step = k - 1
        # front to back: vehicle i initialises its own adjoint, then adds to vehicle i - 1's
        for i in range(n):
            own_v = v[step, i]
            acc = a[step, i]
            adj_next_v = adj_v[i] if own_v + acc * dt > 0.0 else 0.0
            new_x[i] = adj_x[i]
            new_v[i] = adj_x[i] * dt + adj_next_v
            adj_acc = adj_x[i] * half_dt2 + adj_next_v * dt
            # fuel rate f(v, a) = max(rate, floor): the floor passes no gradient
            a_plus = max(acc, 0.0)
            demand = p0 + own_v * (p1 + own_v * p2)
            rate = (
                c0
                + own_v * (c1 + own_v * (c2 + own_v * c3))
                + demand * acc
                + (q0 + q1 * own_v) * a_plus * a_plus
            )
            if rate > (beta if own_v <= cut_speed else 0.0):
                adj_acc += (demand + 2.0 * (q0 + q1 * own_v) * a_plus) * dt * scale
                new_v[i] += (
                    c1
                    + own_v * (2.0 * c2 + 3.0 * c3 * own_v)
                    + (p1 + 2.0 * p2 * own_v) * acc
                    + q1 * a_plus * a_plus
                ) * (dt * scale)
            stop = -own_v / dt
            if i == 0:
                raw = request[step]
                cap = b1 * math.exp(-b2 * own_v) + b3
                gradient[step] = 0.0
                if max(min(raw, cap), -MAX_BRAKING_MPS2) < stop:
                    new_v[i] -= adj_acc / dt
                elif raw > cap:
                    new_v[i] -= adj_acc * b2 * b1 * math.exp(-b2 * own_v)
                elif raw >= -MAX_BRAKING_MPS2:
                    gradient[step] = adj_acc
                continue
            lead_speed = v[step, i - 1]
            gap = x[step, i - 1] - x[step, i] - length
            approach = own_v * (own_v - lead_speed)
            desired = s0 + own_v * tgap + max(0.0, approach) * braking
            model_gap = max(gap, MIN_MODEL_GAP_M)
            ratio = desired / model_gap
            free = own_v / v0
            # d (v/v0)^delta / dv, and (v/v0)^delta itself
            slope = delta * free * free * free if delta == 4.0 else delta * free ** (delta - 1.0)
            free = slope * free / delta
            if amax * (1.0 - free - ratio * ratio) < stop:
                new_v[i] -= adj_acc / dt
                continue
            d_ratio = -2.0 * amax * ratio * adj_acc
            d_desired = d_ratio / model_gap
            if gap > MIN_MODEL_GAP_M:
                d_gap = -d_ratio * desired / (model_gap * model_gap)
                new_x[i - 1] += d_gap
                new_x[i] -= d_gap
            new_v[i] -= adj_acc * amax * slope / v0
            new_v[i] += d_desired * tgap
            if approach > 0.0:
                new_v[i] += d_desired * braking * (2.0 * own_v - lead_speed)
                new_v[i - 1] -= d_desired * braking * own_v
        for i in range(n):
            adj_x[i] = new_x[i]
            adj_v[i] = new_v[i]
    return total_fuel * scale, penalty


_platoon_cost_gradient = cast(
    Callable[..., tuple[float, float]],
    numba.njit(cache=True, fastmath=False)(_platoon_cost_gradient_py),
)


def _sweep_inputs(
    drive: Drive,
    baseline: PlatoonRun,
    bounds: GapBounds,
    settings: OptimumSettings,
    idm: IdmParams,
    model: FuelModel,
) -> tuple[Any, ...]:
    """The adjoint sweep's arguments after the requests, for this drive and its all-human run."""
    dt = drive.dt_s
    leader_fuel_g = float(model.fuel_rate_gps(drive.speed_mps[:-1], drive.accel_mps2[:-1]).sum())
    return (
        drive.position_m,
        drive.speed_mps,
        baseline.position_m[0, 1:].copy(),
        baseline.speed_mps[0, 1:].copy(),
        _idm_coefficients(idm),
        _fuel_coefficients(model),
        _envelope(bounds, settings),
        dt,
        baseline.vehicle_length_m,
        np.concatenate(
            [
                [
                    leader_fuel_g * dt,
                    float(drive.position_m[-1]),
                    _distance_m(baseline),
                    float(baseline.position_m[-1, 1:].sum()) + settings.margin_m,
                ],
                baseline.speed_mps[-1, 1:],
            ]
        ),
    )


def centred_mean(values: FloatArray, window: int) -> FloatArray:
    """Each sample's mean over `window` samples centred on it (fewer at the ends, where the
    window leaves the array): a smoothing that neither lags nor invents samples."""
    half = max(window, 1) // 2
    total = np.concatenate([[0.0], np.cumsum(values, dtype=np.float64)])
    index = np.arange(len(values))
    low = np.maximum(index - half, 0)
    high = np.minimum(index + half + 1, len(values))
    mean: FloatArray = (total[high] - total[low]) / (high - low)
    return mean


def optimal_trajectory(
    drive: Drive,
    *,
    humans: int = HUMANS,
    bounds: GapBounds | None = None,
    settings: OptimumSettings | None = None,
    idm: IdmParams = I24_IDM,
    model: FuelModel = RAV4_2019,
) -> OptimumResult:
    """The fuel-optimal AV trajectory behind this drive's leader, verified in the simulator.

    Starts from the AV driving as the humans do (the all-human run's accelerations, within the
    command range), or as `settings.start_smoothing_s` says, and raises the envelope penalty
    stage by stage (paper sidebar (S4)-(S5)).
    """
    bounds = bounds or GapBounds()
    settings = settings or OptimumSettings()
    if humans < 0:
        raise ValueError(f"humans must not be negative, got {humans}")
    if not drive.position_m[-1] > 0.0:
        raise ValueError(
            f"{drive.name}: the leader never moves, so the platoon's fuel per distance, the "
            "objective, is undefined"
        )
    started = time.perf_counter()
    dt = drive.dt_s
    steps = drive.steps
    baseline = simulate_platoon(drive, platoon_roles(humans + 1, 0), idm=idm)
    per_piece = max(1, round(settings.control_interval_s / dt))
    piece_starts = np.arange(0, steps, per_piece)
    # Unknowns: the AV's speed at the end of each piece (its start speed is given). The
    # accelerations are their differences, so a change moves the trajectory locally instead of
    # shifting every later position (acceleration unknowns make the problem ill-conditioned by
    # the square of the drive's length). Differences outside the command range are clipped in
    # the dynamics, as the car would, and penalised so that the optimum does not lean on it.
    piece_s = np.diff(np.append(piece_starts, steps)) * dt
    start_speed = float(baseline.speed_mps[0, 1])
    ends = np.append(piece_starts[1:], steps)
    guess = (
        centred_mean(drive.speed_mps, round(settings.start_smoothing_s / dt))[ends]
        if settings.start_smoothing_s > 0
        else np.asarray(baseline.speed_mps[ends, 1], dtype=np.float64)
    )
    fixed = _sweep_inputs(drive, baseline, bounds, settings, idm, model)
    gradient = np.zeros(steps)

    def accelerations(speeds: FloatArray) -> tuple[FloatArray, FloatArray]:
        wanted = np.diff(speeds, prepend=start_speed) / piece_s
        return wanted, np.clip(wanted, settings.min_accel_mps2, settings.max_accel_mps2)

    def cost(speeds: FloatArray, weight: float) -> tuple[float, FloatArray]:
        wanted, pieces = accelerations(speeds)
        fuel_g, penalty = _platoon_cost_gradient(
            np.repeat(pieces, per_piece)[:steps], *fixed, weight, gradient
        )
        excess = wanted - pieces
        by_piece = np.add.reduceat(gradient, piece_starts) * (wanted == pieces)
        by_piece += 2.0 * weight * excess * piece_s
        # d accel_j / d speed_j = 1 / tau_j and d accel_{j+1} / d speed_j = -1 / tau_{j+1}
        by_speed = by_piece / piece_s
        by_speed[:-1] -= by_piece[1:] / piece_s[1:]
        return fuel_g + weight * (penalty + float(np.sum(excess * excess * piece_s))), by_speed

    speeds = guess
    iterations = 0
    for weight in settings.penalty_weights:
        budget = settings.max_iterations
        while budget > 0:
            solution = minimize(
                cost,
                speeds,
                args=(weight,),
                jac=True,
                method="L-BFGS-B",
                bounds=[(0.0, None)] * len(speeds),
                options={"maxiter": budget, "maxls": LINE_SEARCH_STEPS},
            )
            iterations += int(solution.nit)
            budget -= max(int(solution.nit), 1)
            improved = float(solution.fun) < cost(speeds, weight)[0] - IMPROVEMENT_G
            speeds = np.asarray(solution.x, dtype=np.float64)
            # A failed line search on a kink of the fuel model (the fuel cut) leaves the
            # quasi-Newton memory useless: start it afresh from there while that still helps.
            if solution.status != ABNORMAL_LINE_SEARCH or not improved:
                break
    accel = np.repeat(accelerations(speeds)[1], per_piece)[:steps]
    run = simulate_platoon(
        drive,
        platoon_roles(humans, 1),
        [ReplayPolicy(accel, dt)],
        idm=idm,
        av_max_accel=lambda speed: float(model.max_accel_mps2(speed)),
    )
    fuel_g = platoon_fuel_g(run, model)
    baseline_fuel_g = platoon_fuel_g(baseline, model)
    economy = platoon_kpis(run, model).fuel_economy_mpg
    baseline_economy = platoon_kpis(baseline, model).fuel_economy_mpg
    envelope = gap_kpis(run.gap_m[:, 0], run.speed_mps[:, 1], run.position_m[:, 1], dt, bounds)
    return OptimumResult(
        drive_name=drive.name,
        accel_mps2=accel,
        fuel_g=fuel_g,
        baseline_fuel_g=baseline_fuel_g,
        fuel_saving_pct=fuel_saving_pct(baseline_economy, economy),
        total_fuel_saving_pct=100.0 * (1.0 - fuel_g / baseline_fuel_g),
        max_gap_m=envelope.max_av_gap_m,
        min_gap_m=float(run.gap_m[:, 0].min()),
        gap_out_of_bounds_s=envelope.gap_out_of_bounds_s,
        time_gap_violation_s=envelope.time_gap_violation_s,
        collisions=run.collisions,
        iterations=iterations,
        seconds=time.perf_counter() - started,
        start_smoothing_s=settings.start_smoothing_s,
        run=run,
    )


# Columns of `smoothfleet sim optimum`'s CSV (the evaluation reads `drive` and
# `fuel_saving_pct`); bump CACHE_VERSION whenever the solver's result can change.
OPTIMUM_COLUMNS = (
    "drive",
    "fuel_saving_pct",
    "total_fuel_saving_pct",
    "max_gap_m",
    "min_gap_m",
    "gap_out_of_bounds_s",
    "time_gap_violation_s",
    "collisions",
    "iterations",
    "seconds",
    "start_smoothing_s",
    # What the bound was computed on (`Drive.fingerprint`, the humans behind the AV), so an
    # evaluation cannot compare a controller with the bound of another cut of a drive.
    "drive_fingerprint",
    "humans",
)
CACHE_VERSION = 2


def result_row(result: OptimumResult) -> dict[str, str | float | int]:
    """One CSV row of a drive's bound (OPTIMUM_COLUMNS)."""
    return {
        "drive": result.drive_name,
        "fuel_saving_pct": round(result.fuel_saving_pct, 4),
        "total_fuel_saving_pct": round(result.total_fuel_saving_pct, 4),
        "max_gap_m": round(result.max_gap_m, 3),
        "min_gap_m": round(result.min_gap_m, 3),
        "gap_out_of_bounds_s": round(result.gap_out_of_bounds_s, 2),
        "time_gap_violation_s": round(result.time_gap_violation_s, 2),
        "collisions": result.collisions,
        "iterations": result.iterations,
        "seconds": round(result.seconds, 2),
        "start_smoothing_s": result.start_smoothing_s,
    }


def best_row(rows: Sequence[Mapping[str, str | float | int]]) -> dict[str, str | float | int]:
    """The bound of a drive solved from several starts: the fewest collisions, then seconds
    under the time gap, then seconds outside the space envelope (a start's result counts in
    full only with none), then the largest fuel saving; the first start wins a tie."""
    if not rows:
        raise ValueError("no result to choose a bound from")

    def rank(row: Mapping[str, str | float | int]) -> tuple[float, float, float, float]:
        return (
            float(row["collisions"]),
            float(row["time_gap_violation_s"]),
            float(row["gap_out_of_bounds_s"]),
            -float(row["fuel_saving_pct"]),
        )

    chosen = min(rows, key=rank)
    return dict(chosen)


def cache_stem(drive_name: str, start_smoothing_s: float) -> str:
    """The cache files' name for a drive and start: the drive's own for the all-human start
    (as before starts could be chosen), `NAME.start60s` for the others."""
    return drive_name if start_smoothing_s == 0 else f"{drive_name}.start{start_smoothing_s:g}s"


def cache_key(
    drive: Drive, humans: int, bounds: GapBounds, settings: OptimumSettings, model: FuelModel
) -> str:
    """What a cached bound was computed from: the drive's speeds and every setting."""
    digest = hashlib.sha256(np.ascontiguousarray(drive.speed_mps).tobytes())
    digest.update(repr((CACHE_VERSION, drive.dt_s, humans, bounds, settings, model)).encode())
    return digest.hexdigest()


def load_cached_row(
    directory: Path, name: str, key: str, start_smoothing_s: float = 0.0
) -> dict[str, str | float | int] | None:
    """The cached row of a drive and start if it was computed from the same inputs, else
    None (rows cached before the start was recorded get it from the settings it is keyed by)."""
    path = directory / f"{cache_stem(name, start_smoothing_s)}.json"
    if not path.is_file():
        return None
    try:
        stored = json.loads(path.read_text())
    except json.JSONDecodeError:
        return None
    if not isinstance(stored, dict) or stored.get("key") != key:
        return None
    row = stored.get("row")
    return {**row, "start_smoothing_s": start_smoothing_s} if isinstance(row, dict) else None


def save_cached(directory: Path, result: OptimumResult, key: str) -> dict[str, str | float | int]:
    """Keep a drive's bound (row and accelerations) so a rerun and the evaluation reuse it."""
    directory.mkdir(parents=True, exist_ok=True)
    row = result_row(result)
    stem = cache_stem(result.drive_name, result.start_smoothing_s)
    np.save(directory / f"{stem}.npy", result.accel_mps2)
    (directory / f"{stem}.json").write_text(json.dumps({"key": key, "row": row}))
    return row


def write_optimum_csv(rows: list[dict[str, str | float | int]], path: Path) -> None:
    """The per-drive bounds as CSV (OPTIMUM_COLUMNS), one row per drive."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=OPTIMUM_COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
