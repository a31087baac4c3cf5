"""`gaussian`: a half-Gaussian looking downstream whose window spans three standard deviations."""

from __future__ import annotations

import numpy as np

from planner.inputs import FloatArray

# sigma = w / 3: the window holds 99.7 % of a Gaussian's one-sided mass, so cutting it there
# changes the average by well under a percent.
SIGMAS_PER_WINDOW = 3.0


def gaussian_kernel(fraction: FloatArray) -> FloatArray:
    """K = exp(-(3 r)^2 / 2)."""
    weights: FloatArray = np.exp(-0.5 * (SIGMAS_PER_WINDOW * fraction) ** 2)
    return weights
