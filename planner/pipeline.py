"""The paper's six-step publication sequence over arrays, without a database.

    1 predict INRIX past its latency   -> planner.predict   (lane-averaged, per sub-segment)
    2 fuse the fleet's observations    -> planner.fuse      (lane-level TSE)
    3 forward kernel smoothing         -> planner.smooth    (desired speed profile)
    4 bottleneck identification        -> planner.bottlenecks
    5 buffer design                    -> planner.buffers
    6 publish                          -> planner.warehouse (the database edge)

The algorithms (planner.algorithms) compose these stages; `planner.algorithms.plan_speeds` runs
a registered one on `PlannerInputs` and returns a `Plan`; the simulator calls it with simulated
traffic, the warehouse with the database's.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from planner.bottlenecks import FINDERS, standing_bottlenecks
from planner.buffers import DESIGNERS, Buffer
from planner.fuse import FUSERS
from planner.inputs import BoolArray, CorridorGrid, FloatArray, InrixHistory, LaneObservations
from planner.params import InvalidParams, PlannerParams
from planner.predict import PREDICTORS, oldest_reading_used_s, usable_history
from planner.registry import Registry, UnknownVariant
from planner.smooth import KERNELS, forward_kernel_smooth

# The parameters that name a stage's variant, and the registry each names one from.
STAGE_REGISTRIES: dict[str, Registry[Any]] = {
    "predictor": PREDICTORS,
    "fuser": FUSERS,
    "kernel": KERNELS,
    "bottleneck_finder": FINDERS,
    "buffer_designer": DESIGNERS,
}


def parse_params(values: Mapping[str, Any] | None) -> PlannerParams:
    """User-given parameters, validated, each stage's variant among the registered ones.

    `PlannerParams` holds a variant as its name (the name is stored with every plan); a name
    nobody registered would pass it and fail every cycle from the first, so a server would
    start and publish no plan. Raises InvalidParams naming the parameter."""
    params = PlannerParams.parse(dict(values or {}))
    for name, registry in STAGE_REGISTRIES.items():
        try:
            registry.get(getattr(params, name))
        except UnknownVariant as error:
            raise InvalidParams(f"planner parameter {name}: {error}") from None
    return params


@dataclass(frozen=True)
class PlannerInputs:
    """Everything one planner cycle reads.

    `previous_smoothed` are the smoothed lane profiles of the recent cycles, newest first (the
    memory that tells a standing bottleneck from a moving wave).
    """

    grid: CorridorGrid
    inrix: InrixHistory
    observations: LaneObservations
    now_s: float
    previous_smoothed: Sequence[FloatArray] = field(default_factory=tuple)


@dataclass(frozen=True)
class Plan:
    """A computed plan: targets per lane and sub-segment, and what they were made from."""

    algorithm: str
    params: PlannerParams
    inrix_as_of_s: float
    # The oldest reading the newest snapshot carried forward for a segment it did not read
    # (`oldest_reading_used_s`); inrix_as_of_s when it read them all.
    inrix_oldest_used_s: float
    tse_mps: FloatArray
    smoothed_mps: FloatArray
    target_mps: FloatArray
    is_buffer: BoolArray
    bottleneck_candidates: BoolArray
    standing_bottlenecks: BoolArray
    buffers: tuple[Buffer, ...] = ()


@dataclass(frozen=True)
class EnhancedTse:
    """Steps 1-2's result: the lane-level TSE and how old the INRIX under it is."""

    tse_mps: FloatArray
    # The newest snapshot used, and the oldest reading it carried forward.
    inrix_as_of_s: float
    inrix_oldest_used_s: float


def enhance_tse(inputs: PlannerInputs, params: PlannerParams) -> EnhancedTse:
    """Steps 1-2: the lane-level TSE and the times of the INRIX it was made from."""
    history = usable_history(inputs.inrix, inputs.now_s, params)
    predictor = PREDICTORS.get(params.predictor)
    prior = predictor(history, inputs.grid.center_x_m, inputs.now_s, params)
    fuser = FUSERS.get(params.fuser)
    return EnhancedTse(
        tse_mps=fuser(prior, inputs.observations, inputs.grid, params),
        inrix_as_of_s=float(history.measured_at_s[-1]),
        inrix_oldest_used_s=oldest_reading_used_s(history, inputs.now_s, params),
    )


def smooth_tse(tse_mps: FloatArray, grid: CorridorGrid, params: PlannerParams) -> FloatArray:
    """Step 3: the forward kernel average with the configured kernel and window."""
    kernel = KERNELS.get(params.kernel)
    return forward_kernel_smooth(tse_mps, grid, kernel, params.window_m, params.quadrature_step_m)


def identify_bottlenecks(
    smoothed_mps: FloatArray, inputs: PlannerInputs, params: PlannerParams
) -> tuple[BoolArray, BoolArray]:
    """Step 4: this cycle's candidate heads and those standing over the recent cycles."""
    finder = FINDERS.get(params.bottleneck_finder)
    current = finder(smoothed_mps, inputs.grid, params)
    previous = [
        finder(np.asarray(earlier, dtype=np.float64), inputs.grid, params)
        for earlier in inputs.previous_smoothed[: params.standing_cycles - 1]
    ]
    return current, standing_bottlenecks(current, previous, inputs.grid, params)


class NonFiniteTargets(ValueError):
    """A plan whose targets are not all numbers: never published (the cycle fails, recorded)."""


def clip_to_legal_range(
    target_mps: FloatArray, grid: CorridorGrid, params: PlannerParams
) -> FloatArray:
    """Every target within the corridor's legal range (dim_corridor), its top raised by the
    configured allowance over the posted limit (the paper's fleet: 73 mph on a 70 mph road)."""
    ceiling = grid.speed_limit_mps + params.speed_limit_allowance_mps
    clipped: FloatArray = np.clip(target_mps, grid.min_target_speed_mps, ceiling)
    not_numbers = int(np.count_nonzero(~np.isfinite(clipped)))  # np.clip lets NaN through
    if not_numbers:
        raise NonFiniteTargets(
            f"{not_numbers} of the plan's {clipped.size} targets are no number: not published"
        )
    return clipped
