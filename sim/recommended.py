"""The deployment pair's controller, named here and nowhere else (its planner and the planner's
parameters are `planner/recommended.py`, which the server plans with too), and the pairs the
evaluation compares it with.

The pair and its planner parameters were chosen by `smoothfleet sim select` (leave-one-date-out
cross-validation on the shared drives: docs/simulation.md reports the held-out folds only).
`smoothfleet sim evaluate --recommended` evaluates it alone against the all-human baseline;
without controller flags every registered pair is evaluated with it marked.
"""

from __future__ import annotations

from sim.evaluate import ControllerVariant
from vehicle_agent.controllers import CONTROLLERS

# Chosen by `smoothfleet sim select` (docs/simulation.md) in every fold and on all dates: the
# most fuel saved among candidates meeting the aims on the training dates (the ACC-button pairs
# miss them: they give away distance and network speed for their fuel). It drives the
# acceleration interface (the RAV4's).
RECOMMENDED_CONTROLLER = ControllerVariant("rl_accel", "accel")


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
