"""`speed_rise`: a slow cell followed downstream by a clear rise in speed is a bottleneck head.

A cell is a candidate when its smoothed speed is at most `slow_speed_mps` (60 mph) and the
fastest smoothed speed within `rise_distance_m` downstream exceeds it by more than
`min_rise_mps` (4 mph); of each run of such cells the most downstream one is the head.
"""

from __future__ import annotations

import numpy as np

from planner.inputs import BoolArray, CorridorGrid, FloatArray
from planner.params import PlannerParams


def find_speed_rise(
    smoothed_mps: FloatArray, grid: CorridorGrid, params: PlannerParams
) -> BoolArray:
    """Candidate heads, shape (lanes, sub-segments)."""
    centers = grid.center_x_m
    reach = np.searchsorted(centers, centers + params.rise_distance_m, side="right")
    heads = np.zeros(smoothed_mps.shape, dtype=np.bool_)
    for lane, speeds in enumerate(smoothed_mps):
        downstream_max = np.full(grid.cells, -np.inf)
        for cell in range(grid.cells - 1):
            downstream_max[cell] = speeds[cell + 1 : max(reach[cell], cell + 2)].max()
        slow_then_rise = (speeds <= params.slow_speed_mps) & (
            downstream_max - speeds > params.min_rise_mps
        )
        run_ends = slow_then_rise & ~np.append(slow_then_rise[1:], False)
        heads[lane] = run_ends
    return heads
