"""Step 4 interface: find bottleneck heads on the smoothed lane TSE, and tell standing ones.

A finder marks candidate bottleneck *heads* (where a slow region ends and traffic speeds up
downstream) per lane and sub-segment for the current cycle. A candidate seen, within
`match_distance_m` in the same lane, in at least `standing_required` of the last
`standing_cycles` cycles (this one included) is *standing*; the others are moving waves, which
the kernel smoothing alone handles.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from planner.inputs import BoolArray, CorridorGrid, FloatArray
from planner.params import PlannerParams


class BottleneckFinder(Protocol):
    """A bottleneck identification variant (registered in planner.bottlenecks.FINDERS)."""

    def __call__(
        self, smoothed_mps: FloatArray, grid: CorridorGrid, params: PlannerParams
    ) -> BoolArray:
        """Candidate heads, shape (lanes, sub-segments)."""
        ...


def standing_bottlenecks(
    current: BoolArray,
    previous: Sequence[BoolArray],
    grid: CorridorGrid,
    params: PlannerParams,
) -> BoolArray:
    """Current candidates seen in enough recent cycles; `previous` is newest first."""
    cycles = [current, *previous[: params.standing_cycles - 1]]
    centers = grid.center_x_m
    near = np.abs(centers[:, None] - centers[None, :]) <= params.match_distance_m
    seen_in = np.zeros(current.shape, dtype=np.int64)
    for candidates in cycles:
        if candidates.shape != current.shape:
            raise ValueError(
                f"bottleneck history of shape {candidates.shape} does not match {current.shape}"
            )
        seen_in += (candidates.astype(np.int64) @ near.T.astype(np.int64)) > 0
    standing: BoolArray = current & (seen_in >= params.standing_required)
    return standing
