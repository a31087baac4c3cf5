"""`queue_storage`: a buffer long enough to hold the queue's vehicles at the buffer's speed.

For a standing bottleneck the queue is the run of slow cells (fused TSE at most
`slow_speed_mps`) holding its head, or the first one within the smoothing window downstream of
it. The queue holds N = sum k(v_i) L_i vehicles per lane (IDM equilibrium density k, see
contract.idm). The buffer drives at v_b = the queue's slowest speed + `buffer_speed_margin_mps`;
to hold the same N vehicles at that speed it needs L_b = N / k(v_b) metres, which end where the
queue starts. Upstream of it the ceiling ramps down at `ramp_decel_mps2`:
v(x) = sqrt(v_b^2 + 2 a (x_b - x)), so the fleet arrives at v_b without braking hard, and the
queue's inflow is spread over the buffer instead of piling into the bottleneck (the paper's
aim of distributing the congested density uniformly over the region of interest).
"""

from __future__ import annotations

import numpy as np

from contract.idm import I24_IDM, equilibrium_density_per_m
from planner.buffers.base import Buffer, BufferDesign
from planner.inputs import BoolArray, CorridorGrid, FloatArray
from planner.params import PlannerParams


def _queue_cells(
    slow: BoolArray, head: int, centers: FloatArray, reach_m: float
) -> tuple[int, int] | None:
    """First and last cell of the slow run holding `head`, or the next one within reach."""
    cell = head
    while cell < len(slow) and not slow[cell]:
        if centers[cell] - centers[head] > reach_m:
            return None
        cell += 1
    if cell == len(slow):
        return None
    first = cell
    while first > 0 and slow[first - 1]:
        first -= 1
    last = cell
    while last + 1 < len(slow) and slow[last + 1]:
        last += 1
    return first, last


def design_queue_storage(
    tse_mps: FloatArray,
    smoothed_mps: FloatArray,
    standing: BoolArray,
    grid: CorridorGrid,
    params: PlannerParams,
) -> BufferDesign:
    """A ramped buffer upstream of every standing bottleneck's queue."""
    centers = grid.center_x_m
    ceiling = np.full(tse_mps.shape, np.inf)
    buffers: list[Buffer] = []
    designed: set[tuple[int, int]] = set()
    for lane_index, head in zip(*np.nonzero(standing), strict=True):
        speeds = tse_mps[lane_index]
        queue = _queue_cells(speeds <= params.slow_speed_mps, int(head), centers, params.window_m)
        if queue is None or (int(lane_index), queue[0]) in designed:
            continue
        designed.add((int(lane_index), queue[0]))
        first, last = queue
        queue_speeds = speeds[first : last + 1]
        vehicles = float(
            np.sum(
                equilibrium_density_per_m(I24_IDM, queue_speeds) * grid.length_m[first : last + 1]
            )
        )
        buffer_speed = float(queue_speeds.min()) + params.buffer_speed_margin_mps
        buffer_length = vehicles / float(equilibrium_density_per_m(I24_IDM, buffer_speed))
        queue_start = float(grid.start_x_m[first])
        plateau_start = queue_start - buffer_length
        upstream = centers < queue_start
        distance_before = np.clip(plateau_start - centers, 0.0, None)
        lane_ceiling = np.where(
            upstream,
            np.sqrt(buffer_speed**2 + 2.0 * params.ramp_decel_mps2 * distance_before),
            np.inf,
        )
        ceiling[lane_index] = np.minimum(ceiling[lane_index], lane_ceiling)
        lowered = upstream & (lane_ceiling < smoothed_mps[lane_index])
        if not lowered.any():
            continue
        end_cell = int(np.nonzero(lowered)[0].max())
        start_cell = end_cell
        while start_cell > 0 and lowered[start_cell - 1]:
            start_cell -= 1
        buffers.append(
            Buffer(
                lane=int(lane_index) + 1,
                start_x_m=float(grid.start_x_m[start_cell]),
                end_x_m=float(grid.end_x_m[end_cell]),
                target_speed_mps=buffer_speed,
                queue_vehicles=vehicles,
            )
        )
    return BufferDesign(ceiling, tuple(buffers))
