"""Key performance indicators of a simulation, as the paper's section "Candidate Controller
Selection" defines them, plus comfort and safety figures.

All functions take arrays with one row per time step and one column per vehicle and are pure.

- fuel economy: total distance of all vehicles / total fuel of all vehicles, in mpg (paper eq.),
  over the simulated vehicles (AVs and humans): the leader replays a measured drive that is the
  same in every run, so its fuel is the boundary condition, not an outcome;
- throughput: vehicles crossing a point per hour, averaged over five equi-spaced points (for a
  finite platoon: (n - 1) intervals over the time between the first and the last crossing),
  counting **every** vehicle that crosses, the leader included (paper "Candidate Controller
  Selection": "counting the number of vehicles crossing various positions"), so a gap an AV
  opens behind the leader costs throughput like any other;
- network speed: total distance / total driving time;
- comfort: RMS acceleration and RMS jerk; safety: minimum gap and minimum time-to-collision.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from contract.units import METRES_PER_MILE
from sim.energy import RAV4_2019, FuelModel
from sim.platoon import PlatoonRun

FloatArray = NDArray[np.float64]

THROUGHPUT_POINTS = 5
SECONDS_PER_HOUR = 3600.0

# The three KPIs the paper selects controllers by ("Candidate Controller Selection").
PAPER_KPIS = ("fuel_economy_mpg", "throughput_vph", "network_speed_mps")
# The paper KPI each per-run column compares (`sim.evaluate`'s rows, `sim.rl.scores`' drive
# scores): a drive whose all-human platoon cannot measure that KPI is left out of the column's
# means, for every controller alike.
COLUMN_KPI = {
    "fuel_saving_pct": "fuel_economy_mpg",
    "fuel_economy_mpg_change_pct": "fuel_economy_mpg",
    "throughput_change_pct": "throughput_vph",
    "throughput_vph_change_pct": "throughput_vph",
    "network_speed_change_pct": "network_speed_mps",
    "network_speed_mps_change_pct": "network_speed_mps",
}
# The per-run column naming the paper KPIs the run's all-human baseline cannot measure,
# `;`-separated (empty: it measures all three).
UNMEASURED_COLUMN = "unmeasured_by_baseline"


@dataclass(frozen=True)
class Kpis:
    """The KPIs of one run (see the module docstring for definitions)."""

    fuel_economy_mpg: float
    throughput_vph: float
    network_speed_mps: float
    accel_rms_mps2: float
    jerk_rms_mps3: float
    min_gap_m: float
    min_ttc_s: float
    collisions: int
    gap_violations: int

    def as_dict(self) -> dict[str, float]:
        """Field name -> value, for tables and CSV rows."""
        return {name: float(value) for name, value in asdict(self).items()}


def unmeasured_paper_kpis(baseline: Kpis) -> tuple[str, ...]:
    """The paper KPIs the all-human `baseline` gives no figure for (0 or not finite: a drive
    too short for the platoon's tail to pass where its leader started, a leader that never
    moves). Every controller's change against such a figure is undefined through no fault of
    its own."""
    return tuple(
        kpi
        for kpi in PAPER_KPIS
        if (value := float(getattr(baseline, kpi))) == 0 or not math.isfinite(value)
    )


def measured_values(rows: Sequence[Mapping[str, Any]], column: str) -> list[float]:
    """A per-run column's values over the rows whose baseline measures its KPI. A row whose own
    value is undefined where the baseline's is not still counts: its NaN is the controller's
    failure (it stalled the platoon), not the drive's."""
    kpi = COLUMN_KPI.get(column)
    return [
        float(row[column])
        for row in rows
        if kpi is None or kpi not in str(row.get(UNMEASURED_COLUMN, "")).split(";")
    ]


def measured_mean(rows: Sequence[Mapping[str, Any]], column: str) -> float:
    """The mean of `measured_values` (NaN when no row's baseline measures the KPI, or when a
    counted row is itself undefined)."""
    values = measured_values(rows, column)
    return float(np.mean(values)) if values else float("nan")


def fuel_economy_mpg(
    position_m: FloatArray, speed_mps: FloatArray, dt_s: float, model: FuelModel = RAV4_2019
) -> float:
    """Miles per gallon of all vehicles together (paper eq. for fuel economy).

    Each step k contributes f(v_k, a_k) dt, a_k being the acceleration applied over the step.
    """
    accel = np.diff(speed_mps, axis=0) / dt_s
    fuel_g = float(model.fuel_rate_gps(speed_mps[:-1], accel).sum() * dt_s)
    distance_m = float((position_m[-1] - position_m[0]).sum())
    if fuel_g <= 0:
        raise ValueError("no fuel was burnt: fuel economy is undefined")
    return (distance_m / METRES_PER_MILE) / (fuel_g * model.gallons_per_gram)


def fuel_saving_pct(baseline_mpg: float, mpg: float) -> float:
    """The drop in fuel per distance against the baseline, in % (positive = less fuel):
    1 - mpg_baseline / mpg (paper, "Candidate Controller Selection"). NaN where it is undefined:
    a platoon that travelled no distance (a leader that never moved) has 0 mpg either way."""
    if mpg == 0 or not math.isfinite(baseline_mpg) or not math.isfinite(mpg):
        return float("nan")
    return 100.0 * (1.0 - baseline_mpg / mpg)


def change_pct(value: float, baseline: float) -> float:
    """A KPI's change against the baseline's, in %; NaN where it is undefined (a baseline of 0,
    such as the throughput of a platoon that never moved, or a non-finite value)."""
    if baseline == 0 or not math.isfinite(baseline) or not math.isfinite(value):
        return float("nan")
    return 100.0 * (value / baseline - 1.0)


def distance_lost_m(
    baseline_final_m: FloatArray, final_m: FloatArray, av_columns: Sequence[int]
) -> float:
    """How much further behind the leader the AVs ended than the humans in their places: the
    largest of the AV columns' final positions in the all-human platoon minus their own (a
    controller may not win fuel by dropping back)."""
    columns = list(av_columns)
    return float(np.max(baseline_final_m[columns] - final_m[columns]))


def crossing_times_s(position_m: FloatArray, dt_s: float, point_m: float) -> FloatArray:
    """When each vehicle first reaches `point_m` (linear between steps; positions never
    decrease), as a detector at the point counts it: a car that stops there counts when it
    arrives, not when it leaves.

    A column that is NaN where the vehicle was not in the lane (a car that merged in) crosses
    only if it was in the lane when it passed the point; otherwise its time is NaN.
    """
    time_s = np.arange(position_m.shape[0], dtype=np.float64) * dt_s
    times = np.full(position_m.shape[1], np.nan)
    for column in range(position_m.shape[1]):
        track = position_m[:, column]
        present = np.isfinite(track)
        if present.all():
            times[column] = _first_arrival_s(track, time_s, point_m)
        elif present.any() and track[present][0] <= point_m <= track[present][-1]:
            times[column] = _first_arrival_s(track[present], time_s[present], point_m)
    return times


def _first_arrival_s(track: FloatArray, time_s: FloatArray, point_m: float) -> float:
    """The first time a non-decreasing `track` reaches `point_m` (its ends outside: clamped,
    as `np.interp` does)."""
    reached = int(np.searchsorted(track, point_m, side="left"))
    if reached == 0:
        return float(time_s[0])
    if reached == track.size:
        return float(time_s[-1])
    before, after = track[reached - 1], track[reached]
    share = (point_m - before) / (after - before)
    return float(time_s[reached - 1] + share * (time_s[reached] - time_s[reached - 1]))


def throughput_at_vph(
    position_m: FloatArray, dt_s: float, point_m: float, merged_m: FloatArray | None = None
) -> float:
    """Vehicles per hour over `point_m`: (n - 1) over the spread of their crossing times.

    `merged_m` holds cars that merged into the lane (NaN before): they count where they crossed
    the point in the lane.
    """
    n = position_m.shape[1]
    if n < 2:
        raise ValueError("throughput needs at least two vehicles")
    if not (position_m[0].max() <= point_m <= position_m[-1].min()):
        raise ValueError(f"not every vehicle passes {point_m:.0f} m during the run")
    times = crossing_times_s(position_m, dt_s, point_m)
    if merged_m is not None and merged_m.shape[1]:
        merged = crossing_times_s(merged_m, dt_s, point_m)
        n += int(np.count_nonzero(np.isfinite(merged)))
    spread = float(times.max() - times.min())
    if spread <= 0:
        raise ValueError(f"all vehicles cross {point_m:.0f} m at once: throughput undefined")
    return float((n - 1) / spread * SECONDS_PER_HOUR)


def shares_a_stretch(position_m: FloatArray) -> bool:
    """Whether the platoon's last vehicle gets, before the run ends, past where its first
    vehicle started: only then is there a point every vehicle crosses during the run."""
    return bool(position_m[-1].min() > position_m[0].max())


def measurement_points_m(position_m: FloatArray, count: int = THROUGHPUT_POINTS) -> FloatArray:
    """`count` equi-spaced interior points of the stretch every vehicle drives through."""
    return shared_points_m([position_m], count)


def shared_points_m(
    positions_m: Sequence[FloatArray], count: int = THROUGHPUT_POINTS
) -> FloatArray:
    """`count` equi-spaced interior points of the stretch every vehicle of every run drives
    through. The paper's measurement locations are the road's: a run and its baseline are
    measured at the same ones, or an AV that drops back would move its own points upstream and
    its change would be taken between two stretches of road."""
    if not all(shares_a_stretch(position_m) for position_m in positions_m):
        raise ValueError("the vehicles share no stretch of road: the drive is too short")
    first = max(float(position_m[0].max()) for position_m in positions_m)
    last = min(float(position_m[-1].min()) for position_m in positions_m)
    points: FloatArray = np.linspace(first, last, count + 2)[1:-1]
    return points


def throughput_vph(
    position_m: FloatArray,
    dt_s: float,
    count: int = THROUGHPUT_POINTS,
    merged_m: FloatArray | None = None,
) -> float:
    """Average throughput over `count` equi-spaced measurement points (paper's definition)."""
    points = measurement_points_m(position_m, count)
    return float(np.mean([throughput_at_vph(position_m, dt_s, p, merged_m) for p in points]))


def network_speed_mps(position_m: FloatArray, dt_s: float) -> float:
    """Total distance of all vehicles over their total driving time."""
    distance = float((position_m[-1] - position_m[0]).sum())
    driving_time = (position_m.shape[0] - 1) * dt_s * position_m.shape[1]
    return float(distance / driving_time)


def accel_rms_mps2(speed_mps: FloatArray, dt_s: float) -> float:
    """Root mean square of the accelerations applied at every step by every vehicle."""
    accel = np.diff(speed_mps, axis=0) / dt_s
    return float(np.sqrt(np.mean(accel**2)))


def jerk_rms_mps3(speed_mps: FloatArray, dt_s: float) -> float:
    """Root mean square of the change of acceleration per second."""
    jerk = np.diff(speed_mps, n=2, axis=0) / (dt_s * dt_s)
    return float(np.sqrt(np.mean(jerk**2))) if jerk.size else 0.0


def min_time_to_collision_s(
    gap_m: FloatArray, speed_mps: FloatArray, lead_speed_mps: FloatArray
) -> float:
    """Smallest gap / closing speed over the moments a vehicle closes in (inf if none does)."""
    closing = speed_mps - lead_speed_mps
    approaching = closing > 0
    if not approaching.any():
        return float("inf")
    # a closing speed of a few ulps (a car that cannot accelerate, creeping) gives a time
    # beyond float range: that is an infinite time to collision, not an error
    with np.errstate(over="ignore"):
        return float((gap_m[approaching] / closing[approaching]).min())


def throughput_points_m(
    runs: Sequence[PlatoonRun], point_m: float | None = None
) -> FloatArray | None:
    """Where the runs' throughput is measured, the same road locations for all of them: the
    five equi-spaced points of the stretch every vehicle of every run drives through
    (`shared_points_m`), or the one point `point_m` (a bottleneck's, just downstream of its
    region; where a platoon's tail has not got that far by the drive's end, the furthest
    point every vehicle of every run reached). None when a run's vehicles share no stretch (a
    stalled platoon: `platoon_kpis` gives it 0)."""
    positions = [run.position_m for run in runs]
    if not all(shares_a_stretch(position_m) for position_m in positions):
        return None
    if point_m is not None:
        reach = min(float(position_m[-1].min()) for position_m in positions)
        return np.array([min(point_m, reach)])
    return shared_points_m(positions)


def run_throughput_vph(
    run: PlatoonRun, points_m: FloatArray, *, cut_ins_counted: bool = True
) -> float:
    """The run's throughput averaged over `points_m`, every vehicle counted (the leader and
    the cars that merged in included), or with `cut_ins_counted=False` the platoon's own.

    The paper counts vehicles crossing positions of the road over all its lanes, where a car
    that changes lanes is counted once whichever lane it crosses in. Here a car that cuts in
    is counted in the platoon's lane and never taken off the lane it left, so a controller
    that opens gaps (and draws cut-ins) gains throughput from them; the platoon's own count
    is the reading such a gain cannot reach (simulator audit, docs/simulation.md)."""
    merged = run.cut_in_position_m if cut_ins_counted else None
    return float(
        np.mean([throughput_at_vph(run.position_m, run.dt_s, point, merged) for point in points_m])
    )


def platoon_kpis(
    run: PlatoonRun,
    model: FuelModel = RAV4_2019,
    *,
    throughput_points_m: FloatArray | None = None,
) -> Kpis:
    """The KPIs of a platoon run: fuel, speed and comfort over its simulated vehicles (columns
    1..N-1); safety (least gap, time to collision, collisions) over every gap someone drove,
    the gaps of the cars that merged in included; throughput over every vehicle, the leader and
    cars that merged in included.

    Throughput is the average over five equi-spaced points of the stretch the run's vehicles
    share, or over `throughput_points_m` (the points a run shares with its baseline,
    `shared_points_m`; the bottleneck's one point just downstream of its region). A platoon
    whose tail never gets past where its leader started (AVs that stalled and held everyone
    behind them) carried no platoon past any point within the run: its throughput counts as 0,
    the only bound the run can prove, so a controller never gains by stranding traffic.
    """
    position = run.position_m[:, 1:]
    speed = run.speed_mps[:, 1:]
    every_gap = run.every_gap_m
    merged = run.cut_in_position_m
    if not shares_a_stretch(run.position_m):
        throughput = 0.0
    elif throughput_points_m is None:
        throughput = throughput_vph(run.position_m, run.dt_s, merged_m=merged)
    else:
        throughput = run_throughput_vph(run, throughput_points_m)
    return Kpis(
        fuel_economy_mpg=fuel_economy_mpg(position, speed, run.dt_s, model),
        throughput_vph=throughput,
        network_speed_mps=network_speed_mps(position, run.dt_s),
        accel_rms_mps2=accel_rms_mps2(speed, run.dt_s),
        jerk_rms_mps3=jerk_rms_mps3(speed, run.dt_s),
        min_gap_m=float(np.nanmin(every_gap)),
        min_ttc_s=min_time_to_collision_s(
            every_gap, run.every_follower_speed_mps, run.every_lead_speed_mps
        ),
        collisions=run.collisions,
        gap_violations=run.gap_violations,
    )
