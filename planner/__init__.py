"""The Speed Planner: pure numerical stages over numpy arrays, and a thin database edge.

Entry point without a database (the simulator's, and any script's)::

    from planner import CorridorGrid, InrixHistory, LaneObservations, PlannerInputs, plan_speeds

    plan = plan_speeds(
        PlannerInputs(grid, inrix_history, observations, now_s, previous_smoothed=()),
        algorithm="kernel_smooth_buffer",      # or "kernel_smooth"
        params=PlannerParams(window_m=1500),   # every knob, validated
    )
    plan.target_mps[lane - 1]                  # target per sub-segment of that lane

Stages (one interface and one registry each; a variant is one module plus one line):
`planner.predict.PREDICTORS`, `planner.fuse.FUSERS`, `planner.smooth.KERNELS`,
`planner.bottlenecks.FINDERS`, `planner.buffers.DESIGNERS`, `planner.algorithms.ALGORITHMS`.
`planner.warehouse` reads the inputs from PostgreSQL and publishes plans (it is the only module
here that knows about the database; the stages never import `app`).
"""

from planner.algorithms import ALGORITHMS, plan_speeds
from planner.buffers import Buffer
from planner.inputs import CorridorGrid, InrixHistory, LaneObservations
from planner.params import InvalidParams, PlannerParams
from planner.pipeline import Plan, PlannerInputs, parse_params
from planner.predict import NoInrixEstimate
from planner.registry import UnknownVariant

__all__ = [
    "ALGORITHMS",
    "Buffer",
    "CorridorGrid",
    "InrixHistory",
    "InvalidParams",
    "LaneObservations",
    "NoInrixEstimate",
    "Plan",
    "PlannerInputs",
    "PlannerParams",
    "UnknownVariant",
    "parse_params",
    "plan_speeds",
]
