"""`triangular`: weight falls linearly from the vehicle's position to the window's far end."""

from __future__ import annotations

import numpy as np

from planner.inputs import FloatArray


def triangular_kernel(fraction: FloatArray) -> FloatArray:
    """K = 1 - r."""
    weights: FloatArray = np.clip(1.0 - fraction, 0.0, 1.0)
    return weights
