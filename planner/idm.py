"""IDM equilibrium spacing and density: how many vehicles a lane holds per metre at a speed.

From ../shared/reference/energy-model.md (the field team's simulator sizes its buffers so):

    s(v) = (s0 + T v) / sqrt(1 - (v / v0)^4),    k(v) = 1 / (s(v) + l)

with the I-24 human-driver IDM s0 = 2 m, T = 1.24 s, v0 = 35 m/s and l = 4 m of vehicle.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from planner.inputs import FloatArray

MIN_GAP_M = 2.0  # s0
TIME_GAP_S = 1.24  # T, the string-unstable I-24 setting
DESIRED_SPEED_MPS = 35.0  # v0
VEHICLE_LENGTH_M = 4.0  # l, added to the gap to get the spacing


def equilibrium_gap_m(speed_mps: ArrayLike) -> FloatArray:
    """Bumper-to-bumper gap s(v) of IDM drivers in equilibrium; infinite at and above v0."""
    v = np.asarray(speed_mps, dtype=np.float64)
    if np.any(v < 0):
        raise ValueError("equilibrium gap: speeds must not be negative")
    with np.errstate(divide="ignore", invalid="ignore"):
        remaining = 1.0 - (v / DESIRED_SPEED_MPS) ** 4
        gap: FloatArray = np.where(
            remaining > 0, (MIN_GAP_M + TIME_GAP_S * v) / np.sqrt(remaining), np.inf
        )
    return gap


def equilibrium_density_per_m(speed_mps: ArrayLike) -> FloatArray:
    """Vehicles per metre of lane k(v) in equilibrium at speed v."""
    density: FloatArray = 1.0 / (equilibrium_gap_m(speed_mps) + VEHICLE_LENGTH_M)
    return density
