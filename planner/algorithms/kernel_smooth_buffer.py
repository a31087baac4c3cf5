"""`kernel_smooth_buffer`: the paper's second variant, all steps (the MVT's choice).

Buffers are designed upstream of standing bottlenecks; elsewhere the smoothed TSE is the plan.
The buffer designer is this project's closed-form stand-in for the paper's RL / PDE-ODE buffer
design (docs/planner.md, step 5).
"""

from __future__ import annotations

from planner.buffers import DESIGNERS, apply_buffers
from planner.params import PlannerParams
from planner.pipeline import (
    Plan,
    PlannerInputs,
    clip_to_legal_range,
    enhance_tse,
    identify_bottlenecks,
    smooth_tse,
)


def kernel_smooth_buffer(inputs: PlannerInputs, params: PlannerParams) -> Plan:
    """Predict, fuse, smooth, find standing bottlenecks, buffer them."""
    enhanced = enhance_tse(inputs, params)
    tse = enhanced.tse_mps
    smoothed = smooth_tse(tse, inputs.grid, params)
    candidates, standing = identify_bottlenecks(smoothed, inputs, params)
    designer = DESIGNERS.get(params.buffer_designer)
    design = designer(tse, smoothed, standing, inputs.grid, params)
    target, is_buffer = apply_buffers(smoothed, design, params)
    return Plan(
        algorithm="kernel_smooth_buffer",
        params=params,
        inrix_as_of_s=enhanced.inrix_as_of_s,
        inrix_oldest_used_s=enhanced.inrix_oldest_used_s,
        tse_mps=tse,
        smoothed_mps=smoothed,
        target_mps=clip_to_legal_range(target, inputs.grid, params),
        is_buffer=is_buffer,
        bottleneck_candidates=candidates,
        standing_bottlenecks=standing,
        buffers=design.buffers,
    )
