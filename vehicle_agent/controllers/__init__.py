"""Vehicle controllers behind one interface (observation in, action out) and their registry.

Usable without CAN or a server: the simulator builds controllers with `build_controller` and calls
`step(Observation)` directly.
"""

from vehicle_agent.controllers.acc_clip import AccClip, clip_speed_setting
from vehicle_agent.controllers.base import (
    AccelCommand,
    AccSetPoint,
    Action,
    Controller,
    NonFiniteAction,
    Observation,
    TargetProfile,
    require_finite,
)
from vehicle_agent.controllers.registry import (
    CONTROLLERS,
    ControllerSpec,
    build_controller,
)

__all__ = [
    "CONTROLLERS",
    "AccClip",
    "AccSetPoint",
    "AccelCommand",
    "Action",
    "Controller",
    "ControllerSpec",
    "NonFiniteAction",
    "Observation",
    "TargetProfile",
    "build_controller",
    "clip_speed_setting",
    "require_finite",
]
