"""Small corridors for the planner's hand-worked tests."""

from __future__ import annotations

import numpy as np

from contract.units import MPS_PER_MPH
from planner.inputs import CorridorGrid


def uniform_grid(cells: int, cell_m: float = 100.0, lanes: int = 1) -> CorridorGrid:
    """`cells` sub-segments of `cell_m` from x = 0, legal range 20-70 mph like the seed."""
    starts = np.arange(cells) * cell_m
    return CorridorGrid(
        corridor_id="TEST",
        lanes=lanes,
        start_x_m=starts,
        end_x_m=starts + cell_m,
        segment_ids=np.arange(1, cells + 1),
        speed_limit_mps=70 * MPS_PER_MPH,
        min_target_speed_mps=20 * MPS_PER_MPH,
    )
