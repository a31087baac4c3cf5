"""The controller registry: each controller name of the contract with its implementation.

A new controller is its params model and schema entry in `contract.controllers` (the server
validates assignments against it) plus one module here (a `Controller` subclass) and one entry
below. The agent builds what the server's config names with `build_controller()`, and so does the
simulator.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from contract.controllers import (
    ACTUATIONS,
    CONTROLLER_SCHEMAS,
    Actuation,
    ControllerConfigError,
    ControllerSchema,
    validate_controller,
)
from vehicle_agent.controllers.acc_clip import AccClip
from vehicle_agent.controllers.base import Controller
from vehicle_agent.controllers.microaccel import MicroAccelController
from vehicle_agent.controllers.microaccel_acc import MicroAccelAccController
from vehicle_agent.controllers.rl_acc import RlAccController
from vehicle_agent.controllers.rl_accel import RlAccelController
from vehicle_agent.controllers.simple import SimpleController


@dataclass(frozen=True)
class ControllerSpec:
    """One registered controller: its contract schema and its constructor."""

    schema: ControllerSchema
    build: Callable[[Actuation, Any], Controller]


BUILDERS: dict[str, Callable[[Actuation, Any], Controller]] = {
    "simple": SimpleController,
    "microaccel": MicroAccelController,
    "microaccel_acc": MicroAccelAccController,
    "rl_acc": RlAccController,
    "rl_accel": RlAccelController,
}
CONTROLLERS: dict[str, ControllerSpec] = {
    name: ControllerSpec(schema, BUILDERS[name]) for name, schema in CONTROLLER_SCHEMAS.items()
}


def build_controller(
    name: str, actuation: str, params: Mapping[str, Any] | None = None
) -> Controller:
    """A ready controller; every `acc` controller comes wrapped in the paper's speed clip."""
    checked: Actuation = "acc" if actuation == "acc" else "accel"
    if actuation not in ACTUATIONS:
        known = ", ".join(ACTUATIONS)
        reason = f"actuation {actuation!r} is not one of {known}"
        raise ControllerConfigError("actuation", reason, reason)
    model = validate_controller(name, actuation, params)
    controller = CONTROLLERS[name].build(checked, model)
    return AccClip(controller) if checked == "acc" else controller
