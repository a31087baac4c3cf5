"""The Intelligent Driver Model (paper sidebar "Car-Following Models"), vectorised over vehicles.

    f(s, v, dv) = a [1 - (v / v0)^delta - (s*(v, dv) / s)^2],
    s*(v, dv) = s0 + v T + max(0, v dv) / (2 sqrt(a b)),

where dv = v - v_lead is the approaching rate. The I-24 parameters of the field team's simulator
(../shared/reference/energy-model.md) are string-unstable, so stop-and-go waves grow along a
platoon of such drivers, as they do on the real road.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

# The IDM's interaction term divides by the gap: a gap at or below this (a collision, which the
# platoon simulator records) is treated as this, so the model still brakes as hard as it can
# instead of producing inf/nan.
MIN_MODEL_GAP_M = 0.01


@dataclass(frozen=True, slots=True)
class IdmParams:
    """IDM parameters: accelerations in m/s^2, speeds in m/s, gaps in m, time gap in s."""

    max_accel_mps2: float = 1.3
    comfortable_decel_mps2: float = 2.0
    delta: float = 4.0
    min_gap_m: float = 2.0
    desired_speed_mps: float = 35.0
    time_gap_s: float = 1.24

    def __post_init__(self) -> None:
        for name in ("max_accel_mps2", "comfortable_decel_mps2", "delta", "desired_speed_mps"):
            if not getattr(self, name) > 0:
                raise ValueError(f"IDM {name} must be positive, got {getattr(self, name)}")
        if self.min_gap_m < 0 or self.time_gap_s < 0:
            raise ValueError("IDM min_gap_m and time_gap_s must not be negative")


# The field team's human driver on I-24 (energy-model.md): string-unstable.
I24_IDM = IdmParams()


def idm_accel(
    params: IdmParams,
    gap_m: ArrayLike,
    speed_mps: ArrayLike,
    lead_speed_mps: ArrayLike,
    desired_speed_mps: ArrayLike | None = None,
) -> FloatArray:
    """IDM acceleration (paper eq. for f_IDM); desired_speed_mps overrides v0 per vehicle."""
    s = np.maximum(np.asarray(gap_m, dtype=np.float64), MIN_MODEL_GAP_M)
    v = np.asarray(speed_mps, dtype=np.float64)
    approaching = v - np.asarray(lead_speed_mps, dtype=np.float64)
    v0 = params.desired_speed_mps if desired_speed_mps is None else np.asarray(desired_speed_mps)
    braking = 1.0 / (2.0 * math.sqrt(params.max_accel_mps2 * params.comfortable_decel_mps2))
    desired_gap = (
        params.min_gap_m + v * params.time_gap_s + np.maximum(0.0, v * approaching) * braking
    )
    result: FloatArray = params.max_accel_mps2 * (
        1.0 - (v / v0) ** params.delta - (desired_gap / s) ** 2
    )
    return result


def equilibrium_gap_m(params: IdmParams, speed_mps: ArrayLike) -> FloatArray:
    """Gap at which an IDM driver keeps speed v behind a leader at v: (s0 + vT)/sqrt(1-(v/v0)^d)."""
    v = np.asarray(speed_mps, dtype=np.float64)
    ratio = v / params.desired_speed_mps
    if np.any(ratio >= 1.0):
        raise ValueError(
            f"no IDM equilibrium at or above the desired speed {params.desired_speed_mps} m/s"
        )
    result: FloatArray = (params.min_gap_m + v * params.time_gap_s) / np.sqrt(
        1.0 - ratio**params.delta
    )
    return result


# l: the length added to the gap to get a vehicle's share of the lane (energy-model.md).
VEHICLE_LENGTH_M = 4.0


def equilibrium_density_per_m(
    params: IdmParams, speed_mps: ArrayLike, vehicle_length_m: float = VEHICLE_LENGTH_M
) -> FloatArray:
    """Vehicles per metre of lane in equilibrium, k(v) = 1 / (s(v) + l); 0 at and above v0.

    At and above the desired speed no gap holds a driver back (the equilibrium gap is unbounded),
    so the lane holds no queue there. The Speed Planner sizes its buffers with it (paper,
    "Buffer design").
    """
    v = np.asarray(speed_mps, dtype=np.float64)
    if np.any(v < 0):
        raise ValueError("equilibrium density: speeds must not be negative")
    below = v < params.desired_speed_mps
    gap = equilibrium_gap_m(params, np.where(below, v, 0.0))
    density: FloatArray = np.where(below, 1.0 / (gap + vehicle_length_m), 0.0)
    return density
