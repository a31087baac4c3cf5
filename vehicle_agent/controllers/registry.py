"""The controller registry: the single source of truth for controller names and actuations.

A new controller is one module (a `Controller` subclass and a pydantic params model) plus one
entry below. The server validates roster rows against `controller_actuations()`, the agent builds
what the server's config names with `build_controller()`, and so does the simulator.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel, ValidationError

from vehicle_agent.controllers.acc_clip import AccClip
from vehicle_agent.controllers.base import ACTUATIONS, Actuation, Controller
from vehicle_agent.controllers.microaccel import MicroAccelController, MicroAccelParams
from vehicle_agent.controllers.microaccel_acc import MicroAccelAccController, MicroAccelAccParams
from vehicle_agent.controllers.simple import SimpleController, SimpleParams


class ControllerConfigError(ValueError):
    """The configured controller name, actuation or params are wrong; the message says which."""


@dataclass(frozen=True)
class ControllerSpec:
    """One registered controller: what it can drive, its params model and its constructor."""

    actuations: frozenset[Actuation]
    params_model: type[BaseModel]
    build: Callable[[Actuation, Any], Controller]
    summary: str


CONTROLLERS: dict[str, ControllerSpec] = {
    "simple": ControllerSpec(
        frozenset({"acc", "accel"}),
        SimpleParams,
        SimpleController,
        "follows the plan's target speed at the vehicle's position, bounded",
    ),
    "microaccel": ControllerSpec(
        frozenset({"accel"}),
        MicroAccelParams,
        MicroAccelController,
        "min(a_safe, a_target, a_MPC) with lane-change recovery (acceleration requests)",
    ),
    "microaccel_acc": ControllerSpec(
        frozenset({"acc"}),
        MicroAccelAccParams,
        MicroAccelAccController,
        "MicroAccel anticipation as ACC speed setting and gap bars",
    ),
}


def controller_actuations() -> dict[str, frozenset[str]]:
    """Controller name -> the actuations it can drive."""
    return {name: frozenset(spec.actuations) for name, spec in CONTROLLERS.items()}


def _describe(error: ValidationError) -> str:
    detail = error.errors()[0]
    where = ".".join(str(part) for part in detail.get("loc", ()))
    return f"params.{where}: {detail.get('msg', 'invalid')}" if where else str(detail.get("msg"))


def validate_params(name: str, params: Mapping[str, Any] | None) -> BaseModel:
    """The controller's params model from a plain mapping (the server's `controller.params`)."""
    spec = CONTROLLERS.get(name)
    if spec is None:
        known = ", ".join(sorted(CONTROLLERS))
        raise ControllerConfigError(f"controller {name!r} is not one of {known}")
    try:
        return spec.params_model.model_validate(dict(params or {}))
    except ValidationError as error:
        raise ControllerConfigError(f"controller {name}: {_describe(error)}") from None


def build_controller(
    name: str, actuation: str, params: Mapping[str, Any] | None = None
) -> Controller:
    """A ready controller; every `acc` controller comes wrapped in the paper's speed clip."""
    model = validate_params(name, params)
    spec = CONTROLLERS[name]
    if actuation not in ACTUATIONS:
        raise ControllerConfigError(f"actuation {actuation!r} is not one of acc, accel")
    if actuation not in spec.actuations:
        raise ControllerConfigError(f"controller {name!r} cannot drive actuation {actuation!r}")
    checked: Actuation = "acc" if actuation == "acc" else "accel"
    controller = spec.build(checked, model)
    return AccClip(controller) if checked == "acc" else controller
