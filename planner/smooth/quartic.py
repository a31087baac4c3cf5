"""`quartic` (biweight): flat near the vehicle, fading smoothly to zero at the window's end."""

from __future__ import annotations

import numpy as np

from planner.inputs import FloatArray


def quartic_kernel(fraction: FloatArray) -> FloatArray:
    """K = (1 - r^2)^2."""
    weights: FloatArray = np.clip(1.0 - fraction**2, 0.0, 1.0) ** 2
    return weights
