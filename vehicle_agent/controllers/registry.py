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


class RegistryMismatch(RuntimeError):
    """A controller with a schema in the contract and no builder here, or the reverse."""


# The contract's schemas (what the server accepts) and the builders (what the car runs) name the
# same controllers: a builder alone was silently left out, and a schema alone was accepted by
# the server for cars that could not build it.
if BUILDERS.keys() != CONTROLLER_SCHEMAS.keys():
    _unbuilt = sorted(CONTROLLER_SCHEMAS.keys() - BUILDERS.keys())
    _unschemed = sorted(BUILDERS.keys() - CONTROLLER_SCHEMAS.keys())
    raise RegistryMismatch(
        f"controllers with a schema but no builder: {_unbuilt}; with a builder but no schema "
        f"in contract.controllers.CONTROLLER_SCHEMAS: {_unschemed}"
    )
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
