"""`uniform`: every point of the window counts the same (the paper's choice, eq. for v_bar)."""

from __future__ import annotations

import numpy as np

from planner.inputs import FloatArray


def uniform_kernel(fraction: FloatArray) -> FloatArray:
    """K = 1 over the window."""
    return np.ones_like(fraction)
