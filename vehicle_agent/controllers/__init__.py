"""Vehicle controllers behind one interface (observation in, action out) and their registry.

Usable without CAN or a server: the simulator builds controllers with `build_controller` and calls
`step(Observation)` directly.
"""

from vehicle_agent.controllers.acc_clip import AccClip, clip_speed_setting
from vehicle_agent.controllers.base import (
    ACTUATIONS,
    AccelCommand,
    AccSetPoint,
    Action,
    Actuation,
    Controller,
    Observation,
    TargetProfile,
)
from vehicle_agent.controllers.registry import (
    CONTROLLERS,
    ControllerConfigError,
    ControllerSpec,
    build_controller,
    controller_actuations,
    validate_params,
)

__all__ = [
    "ACTUATIONS",
    "CONTROLLERS",
    "AccClip",
    "AccSetPoint",
    "AccelCommand",
    "Action",
    "Actuation",
    "Controller",
    "ControllerConfigError",
    "ControllerSpec",
    "Observation",
    "TargetProfile",
    "build_controller",
    "clip_speed_setting",
    "controller_actuations",
    "validate_params",
]
