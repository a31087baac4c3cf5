"""`precedence`: the fleet's own observations win where they exist (paper, "TSE Enhancement").

A lane's sub-segment driven by fleet vehicles in the window takes their ping-weighted mean speed.
Elsewhere the INRIX prior is corrected by the nearby observations' residuals r = observed - prior,
which fade with distance d (length L) and count `other_lane_weight` times for the other lanes:

    v(lane, x) = prior(x) + sum_k w_k r_k / (1 + sum_k w_k),   w_k = exp(-d_k / L) [* lane weight]

The prior counts as one observation of zero residual, so a single distant observation moves an
unobserved cell only a little, and L = 0 is pure precedence. A residual is measured against its
own cell's prior, so next to a slow prior a stopped car's large negative residual could take a
cell below standstill: the corrected estimate is floored at 0 m/s (a lane's traffic does not
reverse, and the buffer design sizes queues from these speeds).
"""

from __future__ import annotations

import numpy as np

from planner.inputs import CorridorGrid, FloatArray, LaneObservations
from planner.params import PlannerParams


def fuse_precedence(
    prior_mps: FloatArray,
    observations: LaneObservations,
    grid: CorridorGrid,
    params: PlannerParams,
) -> FloatArray:
    """Lane-level TSE: observations where driven, the corrected prior elsewhere."""
    tse: FloatArray = np.tile(np.asarray(prior_mps, dtype=np.float64), (grid.lanes, 1))
    mean, counts = observations.pooled(grid)
    observed = counts > 0
    if not observed.any():
        return tse
    source_lane, source_cell = np.nonzero(observed)
    residual = mean[source_lane, source_cell] - tse[source_lane, source_cell]
    centers = grid.center_x_m
    distance = np.abs(centers[:, None] - centers[source_cell][None, :])
    if params.correction_length_m > 0:
        decay = np.exp(-distance / params.correction_length_m)
    else:
        decay = (distance == 0).astype(np.float64)
    for lane in range(grid.lanes):
        lane_weight = np.where(source_lane == lane, 1.0, params.other_lane_weight)
        weights = decay * lane_weight[None, :]
        tse[lane] += (weights @ residual) / (1.0 + weights.sum(axis=1))
    np.maximum(tse, 0.0, out=tse)
    tse[observed] = mean[observed]
    return tse
