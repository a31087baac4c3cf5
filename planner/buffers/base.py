"""Step 5 interface: prescribe deceleration regions (buffers) upstream of standing bottlenecks.

A designer returns a *ceiling* per lane and sub-segment (+inf where it has nothing to say) and
the buffers it made. `apply_buffers` lowers the smoothed profile to the ceiling but never below
`floor_fraction` of it (a buffer slows the fleet a little, it never parks it); everywhere else
the smoothed lane TSE is the plan (paper, six-step sequence, step 5).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from planner.inputs import BoolArray, CorridorGrid, FloatArray
from planner.params import PlannerParams


@dataclass(frozen=True)
class Buffer:
    """One deceleration region: from where it starts slowing to where the queue begins."""

    lane: int
    start_x_m: float
    end_x_m: float
    target_speed_mps: float
    queue_vehicles: float


@dataclass(frozen=True)
class BufferDesign:
    """Speed ceilings (lanes, sub-segments; +inf = none) and the buffers behind them."""

    ceiling_mps: FloatArray
    buffers: tuple[Buffer, ...]


class BufferDesigner(Protocol):
    """A buffer design variant (registered in planner.buffers.DESIGNERS)."""

    def __call__(
        self,
        tse_mps: FloatArray,
        smoothed_mps: FloatArray,
        standing: BoolArray,
        grid: CorridorGrid,
        params: PlannerParams,
    ) -> BufferDesign:
        """Ceilings and buffers for the standing bottlenecks."""
        ...


def apply_buffers(
    smoothed_mps: FloatArray, design: BufferDesign, params: PlannerParams
) -> tuple[FloatArray, BoolArray]:
    """Targets (smoothed, lowered to the ceilings, floored) and where a buffer lowered them."""
    lowered: BoolArray = design.ceiling_mps < smoothed_mps
    floor = params.floor_fraction * smoothed_mps
    target: FloatArray = np.where(lowered, np.maximum(design.ceiling_mps, floor), smoothed_mps)
    return target, lowered
