"""The space-gap envelope every automated vehicle is judged against, and its KPIs.

Saving fuel by dropping back is not smoothing: on a real road a large gap fills with cut-ins,
and a small one is unsafe. The paper's RL training bounds the AV's space gap with an
intervention penalty below h_min and above h_max (section "ACC-Based Controller", reward
r_t); the field team's trajectory environment used h_min = 7 m, h_max = 120 m and a 1 s
minimum time gap, the defaults here. The optimal-control sidebar ("Optimized Vehicle
Trajectory") states the same envelope as h_min v + d_min <= gap <= h_max v + d_max.

The upper bound asks the AV to keep up with its leader, and the fleet may not always: no car
drives over the fleet's top speed (the paper's 73 mph, `contract.controllers`), and recorded
leaders drive faster 8 % of the time. So the envelope is also judged to the *reachable*
leader (`reachable_leader_excess_m`): the nearest a car held to the top speed could be behind
the leader. With a leader never over the top speed both judgements are the same.

All functions are pure over arrays with one row per time step and one column per AV.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from contract.controllers import FLEET_TOP_SPEED_MPS

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

# Below this speed (m/s) a time gap means nothing (a queue at standstill).
MIN_TIME_GAP_SPEED_MPS = 1.0


@dataclass(frozen=True, slots=True)
class GapBounds:
    """The envelope: space gap within [min_gap_m, max_gap_m], time gap at least min_time_gap_s."""

    min_gap_m: float = 7.0
    max_gap_m: float = 120.0
    min_time_gap_s: float = 1.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_gap_m < self.max_gap_m:
            raise ValueError(
                f"gap bounds need 0 <= min < max, got [{self.min_gap_m}, {self.max_gap_m}] m"
            )
        if self.min_time_gap_s < 0.0:
            raise ValueError(f"the minimum time gap cannot be negative ({self.min_time_gap_s} s)")

    def outside_space_bounds(self, gap_m: FloatArray) -> BoolArray:
        """Moments the space gap is below min_gap_m or above max_gap_m."""
        gap = np.asarray(gap_m, dtype=np.float64)
        outside: BoolArray = (gap < self.min_gap_m) | (gap > self.max_gap_m)
        return outside

    def under_time_gap(self, gap_m: FloatArray, speed_mps: FloatArray) -> BoolArray:
        """Moments the time gap gap / v is below min_time_gap_s (only while moving)."""
        gap = np.asarray(gap_m, dtype=np.float64)
        speed = np.asarray(speed_mps, dtype=np.float64)
        under: BoolArray = (speed >= MIN_TIME_GAP_SPEED_MPS) & (gap < self.min_time_gap_s * speed)
        return under


@dataclass(frozen=True, slots=True)
class GapKpis:
    """How an AV (or several, summed) kept the envelope over a run."""

    max_av_gap_m: float
    gap_out_of_bounds_s: float
    time_gap_violation_s: float
    # Share of AV-time spent inside the space bounds and at or above the minimum time gap.
    within_bounds_share: float
    # The same, with the upper bound judged to the reachable leader (`reachable_leader_excess_m`).
    within_reachable_bounds_share: float


def reachable_leader_excess_m(
    gap_m: FloatArray, position_m: FloatArray, dt_s: float, top_speed_mps: float
) -> FloatArray:
    """How far each AV's leader is ahead of the nearest a car held to `top_speed_mps` could be
    behind it: the part of the gap no AV under the fleet's top speed could have closed.

    The reachable leader starts at the leader and never passes it; between steps it moves on at
    most the top speed: p[k] = min(r[k], p[k-1] + c), r = position + gap (the leader's rear,
    however far it jumps at a cut-in) and c = top speed x dt. Unrolled, p[k] = min over j <= k
    of r[j] + (k - j) c, one running minimum. Arrays have one row per step, one column per AV.
    """
    gap = np.asarray(gap_m, dtype=np.float64)
    position = np.asarray(position_m, dtype=np.float64)
    if gap.shape != position.shape:
        raise ValueError(f"gaps {gap.shape} and positions {position.shape} differ in shape")
    leader = position + gap
    step = top_speed_mps * dt_s
    travel = step * np.arange(gap.shape[0], dtype=np.float64).reshape((-1,) + (1,) * (gap.ndim - 1))
    reachable = travel + np.minimum.accumulate(leader - travel, axis=0)
    excess: FloatArray = leader - reachable
    return excess


def gap_kpis(
    gap_m: FloatArray,
    speed_mps: FloatArray,
    position_m: FloatArray,
    dt_s: float,
    bounds: GapBounds,
    top_speed_mps: float = FLEET_TOP_SPEED_MPS,
) -> GapKpis:
    """Envelope KPIs of the AV columns: seconds outside, under the time gap, largest gap, and
    the share within, judged to the leader and to the reachable leader."""
    gap = np.asarray(gap_m, dtype=np.float64)
    if gap.size == 0:
        return GapKpis(0.0, 0.0, 0.0, 1.0, 1.0)
    outside = bounds.outside_space_bounds(gap)
    under = bounds.under_time_gap(gap, speed_mps)
    # only the upper bound moves: a gap is too small to the leader the AV has, however fast
    excess = reachable_leader_excess_m(gap, position_m, dt_s, top_speed_mps)
    reachable_outside = (gap < bounds.min_gap_m) | (gap - excess > bounds.max_gap_m)
    return GapKpis(
        max_av_gap_m=float(gap.max()),
        gap_out_of_bounds_s=float(outside.sum() * dt_s),
        time_gap_violation_s=float(under.sum() * dt_s),
        within_bounds_share=float(1.0 - np.mean(outside | under)),
        within_reachable_bounds_share=float(1.0 - np.mean(reachable_outside | under)),
    )
