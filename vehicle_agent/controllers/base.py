"""The controller interface: an observation of the car and its plan in, one action out.

Controllers never touch CAN, HTTP or clocks: the agent builds an `Observation` every control
period (10 Hz) from the decoded car state and the plan, and turns the `Action` into button presses
or acceleration requests behind the safety layer. The simulator calls the same objects directly.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from contract.controllers import Actuation


@dataclass(frozen=True, slots=True)
class TargetProfile:
    """The plan's target speeds along the vehicle's lane, as seen now.

    `shift_m` moves every lookup downstream: a plan published `age` seconds ago describes waves
    that have since travelled `wave_speed * age` (upstream, wave speed < 0), so the target at x now
    is the published target at x - wave_speed * age.
    """

    x_m: NDArray[np.float64]
    target_speed_mps: NDArray[np.float64]
    shift_m: float = 0.0

    def at(self, x_m: float) -> float:
        """Target speed at position x_m (linear between plan points, held flat past its ends)."""
        return float(np.interp(x_m + self.shift_m, self.x_m, self.target_speed_mps))


@dataclass(frozen=True, slots=True)
class Observation:
    """What a controller sees at one control step (SI units unless the name says otherwise)."""

    time_s: float
    speed_mps: float
    target_speed_mps: float
    position_m: float | None = None
    target: TargetProfile | None = None
    # The "minicar" flag: the car's own sensors see a leader (all makes).
    lead_present: bool = False
    # Space gap and lead-minus-ego speed: only where the make senses them (paper Table 2: RAV4).
    lead_distance_m: float | None = None
    lead_rel_speed_mps: float | None = None
    acc_speed_setting_mph: float | None = None
    acc_gap_setting: int | None = None
    # The acceleration the agent's limiter last let through (m/s^2), which its jerk limits
    # start the next request from; the car's own at a take-over. `accel` cars only.
    commanded_accel_mps2: float | None = None

    @property
    def has_lead_state(self) -> bool:
        """True when a leader is seen and its gap and relative speed are measured."""
        return (
            self.lead_present
            and self.lead_distance_m is not None
            and self.lead_rel_speed_mps is not None
            and math.isfinite(self.lead_distance_m)
            and math.isfinite(self.lead_rel_speed_mps)
        )


@dataclass(frozen=True, slots=True)
class AccelCommand:
    """An acceleration request (actuation `accel`)."""

    accel_mps2: float
    # What a trained policy asked for before its safety bound, kept for diagnosis and tests.
    requested_accel_mps2: float = field(default=math.nan, compare=False)
    # The time margin (s) such a policy added to its safety bound's gap; 0 for a plain request.
    time_margin_s: float = field(default=0.0, compare=False)


@dataclass(frozen=True, slots=True)
class AccSetPoint:
    """ACC set points for the stock ACC (actuation `acc`): whole mph and 1..3 gap bars."""

    speed_setting_mph: int
    gap_setting: int
    # What the controller asked for before the paper's clip, kept for telemetry and tests.
    requested_speed_mph: float = field(default=math.nan, compare=False)


Action = AccelCommand | AccSetPoint


class NonFiniteAction(ValueError):
    """A controller asked for a speed or an acceleration that is not a number.

    That is the controller's failure, and the agent hands the car back for it, as for any error a
    controller raises: no clip or limiter may turn it into a setting (the paper's clip would make
    NaN its 20 mph floor, a limiter 0 m/s^2), because nothing decided that value.
    """


def require_finite(action: Action) -> Action:
    """`action`, when every value it asks the car for is a number; else `NonFiniteAction`."""
    if isinstance(action, AccelCommand):
        if not math.isfinite(action.accel_mps2):
            raise NonFiniteAction(f"acceleration request {action.accel_mps2} m/s^2")
    elif not math.isfinite(action.requested_speed_mph):
        raise NonFiniteAction(f"speed setting request {action.requested_speed_mph} mph")
    return action


class Controller(ABC):
    """A vehicle controller: stateful across steps, reset when the agent (re-)engages."""

    name: ClassVar[str]

    def __init__(self, actuation: Actuation) -> None:
        self.actuation = actuation

    @abstractmethod
    def step(self, observation: Observation) -> Action:
        """Decide this control period's action."""

    def reset(self) -> None:  # noqa: B027 - stateless controllers keep the default
        """Forget the past (called whenever the agent takes over from the stock ACC)."""

    @property
    def policy_sha256(self) -> str | None:
        """The sha256 of the trained policy this controller evaluates; None without one."""
        return None
