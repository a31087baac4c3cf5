"""The deployment pair this project recommends, named here and nowhere else, and the pairs the
evaluation compares it with.

The pair and its planner parameters were chosen by `smoothfleet sim select` (leave-one-date-out
cross-validation on the shared drives: docs/simulation.md reports the held-out folds only).
`smoothfleet sim evaluate --recommended` evaluates it alone against the all-human baseline;
without controller flags every registered pair is evaluated with it marked.
"""

from __future__ import annotations

from typing import Any

from sim.evaluate import ControllerVariant
from vehicle_agent.controllers import CONTROLLERS

RECOMMENDED_PLANNER = "kernel_smooth"
# Chosen by `smoothfleet sim select` (docs/simulation.md) in every fold and on all dates: the
# most fuel saved among candidates meeting the aims on the training dates (the ACC-button pairs
# miss them: they give away distance and network speed for their fuel). It drives the
# acceleration interface (the RAV4's); the window is the one chosen on all dates.
RECOMMENDED_CONTROLLER = ControllerVariant("rl_accel", "accel")
# The planner's smoothing window and its allowance over the posted limit (3 mph: the paper's
# fleet drove up to 73 mph on the 70 mph road, its ACC clip).
RECOMMENDED_PLANNER_PARAMS: dict[str, Any] = {
    "window_m": 1500,
    "speed_limit_allowance_mps": 1.34112,
}


def registered_variants() -> list[ControllerVariant]:
    """Every registered controller on every actuation it drives, with its default parameters,
    then the recommended variant if its parameters differ from the defaults."""
    variants = [
        ControllerVariant(name, actuation)
        for name, spec in CONTROLLERS.items()
        for actuation in sorted(spec.schema.actuations)
    ]
    if RECOMMENDED_CONTROLLER not in variants:
        variants.append(RECOMMENDED_CONTROLLER)
    return variants
