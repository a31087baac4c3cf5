"""Step 3: the forward kernel average of the lane-level TSE (paper eq. for the desired speed).

    v_bar(x_a) = int_{x_a}^{x_a + w} K(x_a, x) v(x) dx  /  int_{x_a}^{x_a + w} K(x_a, x) dx

v is the TSE interpolated linearly between sub-segment centres; the integrals are taken by the
trapezoid rule on a fine step. Near the corridor's end the window is cut at the end and the
kernel renormalised over what remains. A kernel is a weight of the offset's fraction of the
window, r = (x - x_a) / w in [0, 1]: looking downstream only, the profile slows *in advance*
of congestion.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from planner.inputs import CorridorGrid, FloatArray


class Kernel(Protocol):
    """A kernel shape (registered in planner.smooth.KERNELS)."""

    def __call__(self, fraction: FloatArray) -> FloatArray:
        """Weight at offset fractions r in [0, 1] of the window."""
        ...


def forward_kernel_smooth(
    tse_mps: FloatArray, grid: CorridorGrid, kernel: Kernel, window_m: float, step_m: float
) -> FloatArray:
    """Desired speed at every sub-segment centre of every lane, shape as `tse_mps`."""
    if window_m <= 0 or step_m <= 0:
        raise ValueError("the smoothing window and quadrature step must be positive")
    tse = np.atleast_2d(np.asarray(tse_mps, dtype=np.float64))
    steps = max(1, math.ceil(window_m / step_m))
    offsets = np.linspace(0.0, window_m, steps + 1)
    trapezoid = np.ones(steps + 1)
    trapezoid[[0, -1]] = 0.5
    centers = grid.center_x_m
    positions = centers[:, None] + offsets[None, :]
    inside = positions <= grid.end_x_m[-1]
    weights = trapezoid[None, :] * kernel(offsets / window_m)[None, :] * inside
    smoothed = np.empty_like(tse)
    for lane in range(tse.shape[0]):
        speeds = np.interp(positions, centers, tse[lane])
        smoothed[lane] = (weights * speeds).sum(axis=1) / weights.sum(axis=1)
    return smoothed
