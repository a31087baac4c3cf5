"""What each trajectory point stands for in Edie's sums: its time step, distance, speed and fuel.

Edie's generalised definitions (paper, "Results") need, per box, the total time vehicles spent
in it, the total distance they travelled in it and the fuel they burnt in it. A MOTION point i of
a trajectory stands for the step to the trajectory's next point:

    dt_i = t_{i+1} - t_i,   dx_i = x_{i+1} - x_i,   v_i = dx_i / dt_i,
    fuel_i = f(v_i, a_i, 0) dt_i            (f: the paper's polynomial energy model, sim.energy)

and a trajectory's last point stands for nothing (dt = dx = 0), so a trajectory's steps add up to
exactly its duration and its length. The acceleration a_i is the change of speed over about one
second around the step (`ACCEL_WINDOW_S`): MOTION positions are 25 Hz, and differencing twice at
0.04 s would turn centimetres of position noise into metres per second squared, which the energy
model's a_+^2 term would turn into fuel. The road grade is taken as 0 (no elevation profile yet).

All functions take many trajectories at once, concatenated, with `starts` (the index of each
trajectory's first point), so a batch of thousands of documents is a handful of numpy calls.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.energy import RAV4_2019, FuelModel

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# Acceleration is the speed change over this span around each step (seconds).
ACCEL_WINDOW_S = 1.0

# The energy model per MOTION coarse vehicle class. The model set (sim.energy) has one fitted
# vehicle, a midsize SUV (the 2019 RAV4); it is used for every class, which overstates a sedan's
# fuel a little and understates a semi's by several times (docs/analytics.md): psi is a field of
# "RAV4-equivalent" fuel, comparable across time and space, not a fuel inventory.
FUEL_MODEL_BY_CLASS: dict[int, FuelModel] = {
    0: RAV4_2019,  # sedan
    1: RAV4_2019,  # midsize (SUV): the fitted vehicle
    2: RAV4_2019,  # van
    3: RAV4_2019,  # pickup
    4: RAV4_2019,  # semi
    5: RAV4_2019,  # truck
    6: RAV4_2019,  # motorcycle
}
DEFAULT_FUEL_MODEL = RAV4_2019


def fuel_model_name(vehicle_class: int) -> str:
    """The energy model used for a MOTION coarse vehicle class."""
    return FUEL_MODEL_BY_CLASS.get(vehicle_class, DEFAULT_FUEL_MODEL).name


@dataclass(frozen=True, slots=True)
class Steps:
    """Per point: the step it stands for, its speed and acceleration, and the fuel of the step."""

    dt_s: FloatArray
    dx_m: FloatArray
    speed_mps: FloatArray
    accel_mps2: FloatArray
    fuel_g: FloatArray


def trajectory_steps(
    time_s: FloatArray, x_m: FloatArray, starts: IntArray, vehicle_class: IntArray
) -> Steps:
    """Steps of concatenated trajectories (time strictly increasing within each one).

    `vehicle_class` is each point's MOTION coarse class, which picks its energy model.
    """
    classes = np.asarray(vehicle_class)
    points = len(time_s)
    ends = np.append(starts[1:], points)
    last = np.zeros(points, dtype=bool)
    last[ends[ends > starts] - 1] = True
    dt = np.zeros(points)
    dx = np.zeros(points)
    dt[:-1] = np.diff(time_s)
    dx[:-1] = np.diff(x_m)
    dt[last] = 0.0
    dx[last] = 0.0
    moving = dt > 0
    speed = np.zeros(points)
    np.divide(dx, dt, out=speed, where=moving)
    # A trajectory's last point keeps the speed of its last step (it stands for no time).
    first = np.zeros(points, dtype=bool)
    first[starts[ends > starts]] = True
    closing = np.flatnonzero(last & ~first)
    speed[closing] = speed[closing - 1]
    accel = windowed_accel(time_s, dt, speed, starts, ends)
    fuel = np.zeros(points)
    for code in np.unique(classes):
        model = FUEL_MODEL_BY_CLASS.get(int(code), DEFAULT_FUEL_MODEL)
        at = classes == code
        fuel[at] = model.fuel_rate_gps(np.maximum(speed[at], 0.0), accel[at]) * dt[at]
    return Steps(dt_s=dt, dx_m=dx, speed_mps=speed, accel_mps2=accel, fuel_g=fuel)


def windowed_accel(
    time_s: FloatArray, dt_s: FloatArray, speed_mps: FloatArray, starts: IntArray, ends: IntArray
) -> FloatArray:
    """Speed change over about ACCEL_WINDOW_S around each step, within its own trajectory.

    a_i = (v_hi - v_lo) / (m_hi - m_lo), m = t + dt / 2 the steps' midpoints, lo and hi the steps
    half a window before and after i, clipped to the trajectory's steps (0 without two steps).
    Half a window is counted in each trajectory's own steps (its median step): counted in the
    batch's, a 10 Hz document imported beside 25 Hz ones was read over 2.5 s, not 1 s, and its
    fuel depended on which documents shared its batch (tests/app/motion/test_kinematics.py).
    """
    points = len(time_s)
    if points == 0:
        return np.zeros(0)
    halves = _half_windows(dt_s, starts, ends)
    kinds = np.unique(halves)
    if len(kinds) == 1:
        return _accel_with_half(time_s, dt_s, speed_mps, starts, ends, int(kinds[0]))
    accel = np.zeros(points)
    for half in kinds.tolist():
        chosen = halves == half
        lengths = ends[chosen] - starts[chosen]
        at = np.concatenate(
            [np.arange(a, b) for a, b in zip(starts[chosen], ends[chosen], strict=True)]
        )
        own_ends = np.cumsum(lengths)
        accel[at] = _accel_with_half(
            time_s[at], dt_s[at], speed_mps[at], own_ends - lengths, own_ends, int(half)
        )
    return accel


def _half_windows(dt_s: FloatArray, starts: IntArray, ends: IntArray) -> IntArray:
    """Half of ACCEL_WINDOW_S in steps of each trajectory's own median step, rounded half up
    with a margin for the timestamps' float noise (MOTION's 25 Hz steps read 0.03999996 s, and
    12.5 steps must not become 12 on one trajectory and 13 on the next); at least 1.

    Trajectories whose steps are all alike (MOTION's, but for a lost point) take their mean
    step, in a few array passes; only the others pay for a median each.
    """
    steps = np.maximum(ends - starts - 1, 0)
    halves = np.ones(len(starts), dtype=np.int64)
    has_steps = steps > 0
    if not has_steps.any():
        return halves
    first, last = starts[has_steps], starts[has_steps] + steps[has_steps]
    # each trajectory's steps are dt_s[first:last]; reduceat over their concatenation
    at = np.concatenate([[0], np.cumsum(steps[has_steps])[:-1]])
    own = np.concatenate([dt_s[a:b] for a, b in zip(first, last, strict=True)])
    widest, narrowest = np.maximum.reduceat(own, at), np.minimum.reduceat(own, at)
    typical = np.add.reduceat(own, at) / steps[has_steps]
    uneven = np.flatnonzero(widest - narrowest > 1e-3 * np.maximum(typical, 1e-9))
    for number in uneven.tolist():
        chunk = own[at[number] : at[number] + steps[has_steps][number]]
        positive = chunk[chunk > 0]
        typical[number] = float(np.median(positive)) if len(positive) else 0.0
    with np.errstate(divide="ignore"):
        counted = np.floor(0.5 * ACCEL_WINDOW_S / typical + 0.501)
    halves[has_steps] = np.where(typical > 0, np.maximum(counted, 1), 1).astype(np.int64)
    return halves


def _accel_with_half(
    time_s: FloatArray,
    dt_s: FloatArray,
    speed_mps: FloatArray,
    starts: IntArray,
    ends: IntArray,
    half: int,
) -> FloatArray:
    """`windowed_accel` for trajectories that share one half window (`half` steps)."""
    points = len(time_s)
    midpoint = time_s + 0.5 * dt_s
    accel = np.zeros(points)
    if points > 2 * half:
        # Away from a trajectory's ends: lo = i - half and hi = i + half, plain shifts.
        inner = slice(half, points - half)
        span = midpoint[2 * half :] - midpoint[: points - 2 * half]
        change = speed_mps[2 * half :] - speed_mps[: points - 2 * half]
        np.divide(change, span, out=accel[inner], where=span > 0)
    # Near an end (and at the array's ends): lo and hi clipped to the trajectory's own steps.
    last_step = ends - 2  # a trajectory's last step is its last-but-one point
    offsets = np.arange(half + 1)
    near = np.concatenate(
        [starts[:, None] + offsets[None, :], ends[:, None] - 1 - offsets[None, :]], axis=1
    ).ravel()
    owner = np.repeat(np.arange(len(starts)), 2 * (half + 1))
    valid = (near >= starts[owner]) & (near < ends[owner])
    near, owner = near[valid], owner[valid]
    lo = np.maximum(near - half, starts[owner])
    hi = np.minimum(near + half, last_step[owner])
    usable = hi > lo
    edge = np.zeros(len(near))
    span_near = midpoint[np.where(usable, hi, lo)] - midpoint[lo]
    np.divide(
        speed_mps[np.where(usable, hi, lo)] - speed_mps[lo],
        span_near,
        out=edge,
        where=usable & (span_near > 0),
    )
    accel[near] = edge
    return accel


@dataclass(frozen=True, slots=True)
class CellRuns:
    """Steps summed per trajectory, lane and cell of the base grid (one row per run of points)."""

    first_point: IntArray
    t_cell_s: FloatArray
    x_cell_m: FloatArray
    time_s: FloatArray
    distance_m: FloatArray
    fuel_g: FloatArray
    points: IntArray


def cell_runs(
    time_s: FloatArray,
    x_m: FloatArray,
    lane: NDArray[np.int16],
    trajectory: IntArray,
    steps: Steps,
    cell_t_s: float,
    cell_x_m: float,
) -> CellRuns:
    """Edie's totals of each run of consecutive points in one trajectory, lane and cell.

    Points of a trajectory are in time order, so a cell is entered and left a few times at
    most: summing runs (np.add.reduceat) needs no sort. A box made of whole cells sums its
    cells' rows exactly as it would sum its points (app.motion.edie).
    """
    t_cell = np.floor(time_s / cell_t_s) * cell_t_s
    x_cell = np.floor(x_m / cell_x_m) * cell_x_m
    change = np.ones(len(time_s), dtype=bool)
    change[1:] = (
        (t_cell[1:] != t_cell[:-1])
        | (x_cell[1:] != x_cell[:-1])
        | (lane[1:] != lane[:-1])
        | (trajectory[1:] != trajectory[:-1])
    )
    first = np.flatnonzero(change)
    counts = np.diff(np.append(first, len(time_s)))
    return CellRuns(
        first_point=first,
        t_cell_s=t_cell[first],
        x_cell_m=x_cell[first],
        time_s=np.add.reduceat(steps.dt_s, first) if len(first) else np.zeros(0),
        distance_m=np.add.reduceat(steps.dx_m, first) if len(first) else np.zeros(0),
        fuel_g=np.add.reduceat(steps.fuel_g, first) if len(first) else np.zeros(0),
        points=counts.astype(np.int64),
    )
