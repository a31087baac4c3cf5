"""`kernel_smooth`: the paper's first Speed Planner variant, steps 1-3 (no buffers).

The smoothed lane-level TSE, clipped to the legal range, is the plan.
"""

from __future__ import annotations

import numpy as np

from planner.params import PlannerParams
from planner.pipeline import Plan, PlannerInputs, clip_to_legal_range, enhance_tse, smooth_tse


def kernel_smooth(inputs: PlannerInputs, params: PlannerParams) -> Plan:
    """Predict, fuse, smooth."""
    enhanced = enhance_tse(inputs, params)
    tse = enhanced.tse_mps
    smoothed = smooth_tse(tse, inputs.grid, params)
    nothing = np.zeros(tse.shape, dtype=np.bool_)
    return Plan(
        algorithm="kernel_smooth",
        params=params,
        inrix_as_of_s=enhanced.inrix_as_of_s,
        inrix_oldest_used_s=enhanced.inrix_oldest_used_s,
        tse_mps=tse,
        smoothed_mps=smoothed,
        target_mps=clip_to_legal_range(smoothed, inputs.grid, params),
        is_buffer=nothing,
        bottleneck_candidates=nothing,
        standing_bottlenecks=nothing,
    )
