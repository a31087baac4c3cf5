"""Step 3: the forward kernel average (paper eq. for the desired speed profile)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.smooth import KERNELS, forward_kernel_smooth
from tests.planner.grids import uniform_grid

GRID = uniform_grid(150)  # 15 km of 100 m cells, centres at 50, 150, ...


def test_uniform_average_over_a_step_into_congestion() -> None:
    # 30 m/s up to 5 km, 10 m/s beyond. At the centre 4450 m the 1500 m window holds 550 m
    # fast and 950 m slow: (550 x 30 + 950 x 10) / 1500 = 17.333 m/s (the interpolated ramp
    # between the centres 4950 and 5050 m integrates to the same as the step).
    tse = np.where(GRID.center_x_m < 5000, 30.0, 10.0)[None, :]
    smoothed = forward_kernel_smooth(tse, GRID, KERNELS.get("uniform"), 1500.0, 10.0)
    assert smoothed[0, 44] == pytest.approx(26000 / 1500)
    # Entirely upstream of the window's reach it is still free flow; inside the jam, jam speed.
    assert smoothed[0, 30] == pytest.approx(30.0)
    assert smoothed[0, 60] == pytest.approx(10.0)


@pytest.mark.parametrize(
    ("kernel", "mean_offset_fraction"),
    [
        ("uniform", 1 / 2),
        ("triangular", 1 / 3),  # int r(1-r) / int (1-r)
        ("quartic", 15 / 48),  # int r(1-r^2)^2 / int (1-r^2)^2 = (1/6) / (8/15)
        (
            "gaussian",  # half-normal with sigma = w/3, cut at 3 sigma
            ((1 - math.exp(-4.5)) / 9)
            / (math.sqrt(math.pi) / (2 * math.sqrt(4.5)) * math.erf(3 / math.sqrt(2))),
        ),
    ],
)
def test_a_linear_profile_is_read_at_the_kernels_mean_offset(
    kernel: str, mean_offset_fraction: float
) -> None:
    # For v(x) = 10 + 0.001 x the kernel average is v at x + E[u], the kernel's mean offset.
    tse = (10.0 + 0.001 * GRID.center_x_m)[None, :]
    smoothed = forward_kernel_smooth(tse, GRID, KERNELS.get(kernel), 1500.0, 5.0)
    x = GRID.center_x_m[40]
    assert smoothed[0, 40] == pytest.approx(
        10.0 + 0.001 * (x + 1500 * mean_offset_fraction), abs=1e-3
    )


def test_the_window_is_cut_at_the_corridors_end() -> None:
    # At the last centre (14950 m) only 50 m remain; the profile beyond the last centre is flat.
    tse = (10.0 + 0.001 * GRID.center_x_m)[None, :]
    smoothed = forward_kernel_smooth(tse, GRID, KERNELS.get("uniform"), 1500.0, 5.0)
    assert smoothed[0, -1] == pytest.approx(10.0 + 0.001 * 14950)
    # 950 m from the end (centre 14050 m) the window holds 900 m of the slope, whose mean is
    # v(14500) = 24.5, and 50 m held flat at v(14950) = 24.95: (900 x 24.5 + 50 x 24.95) / 950.
    # The whole 1500 m window would read 24.68 there.
    assert smoothed[0, -10] == pytest.approx((900 * 24.5 + 50 * 24.95) / 950, abs=2e-3)


def test_every_lane_is_smoothed_on_its_own() -> None:
    tse = np.vstack([np.full(GRID.cells, 30.0), np.full(GRID.cells, 12.0)])
    smoothed = forward_kernel_smooth(tse, GRID, KERNELS.get("quartic"), 1000.0, 10.0)
    assert np.allclose(smoothed[0], 30.0)
    assert np.allclose(smoothed[1], 12.0)
