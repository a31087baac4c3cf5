"""Each MOTION point's step for Edie's sums, worked by hand."""

from __future__ import annotations

import numpy as np
import pytest

from app.motion.kinematics import trajectory_steps
from sim.energy import RAV4_2019


def test_constant_speed_steps_time_distance_and_fuel() -> None:
    # Two trajectories: 3 points at 20 m/s every 0.5 s, then 2 points at 10 m/s 1 s apart.
    time_s = np.array([0.0, 0.5, 1.0, 7.0, 8.0])
    x_m = np.array([100.0, 110.0, 120.0, 0.0, 10.0])
    steps = trajectory_steps(time_s, x_m, np.array([0, 3]), np.array([1, 1, 1, 0, 0]))
    assert steps.dt_s.tolist() == [0.5, 0.5, 0.0, 1.0, 0.0]
    assert steps.dx_m.tolist() == [10.0, 10.0, 0.0, 10.0, 0.0]
    assert steps.speed_mps.tolist() == [20.0, 20.0, 20.0, 10.0, 10.0]
    assert steps.accel_mps2.tolist() == [0.0] * 5
    # f(20, 0) = 0.60936 g/s and f(10, 0) = 0.29554 g/s (docs/analytics.md).
    assert steps.fuel_g == pytest.approx(
        [0.5 * 0.60936, 0.5 * 0.60936, 0.0, 0.29554, 0.0], abs=1e-5
    )


def test_acceleration_is_the_speed_change_over_about_a_second() -> None:
    # 25 Hz, a = 1 m/s^2 from 10 m/s for 4 s: x = 10 t + t^2 / 2.
    time_s = np.arange(0.0, 4.0001, 0.04)
    x_m = 10 * time_s + 0.5 * time_s**2
    steps = trajectory_steps(time_s, x_m, np.array([0]), np.zeros(len(time_s), dtype=np.int64))
    inner = slice(1, -2)
    assert steps.accel_mps2[inner] == pytest.approx(1.0, abs=1e-6)
    # Speed over a step is the speed at its midpoint.
    assert steps.speed_mps[:-1] == pytest.approx(10 + time_s[:-1] + 0.02)
    expected_fuel = RAV4_2019.fuel_rate_gps(steps.speed_mps, steps.accel_mps2) * steps.dt_s
    assert steps.fuel_g == pytest.approx(expected_fuel)
    assert steps.dx_m.sum() == pytest.approx(x_m[-1] - x_m[0])
    assert steps.dt_s.sum() == pytest.approx(4.0)


def test_a_single_point_trajectory_stands_for_nothing() -> None:
    steps = trajectory_steps(np.array([5.0]), np.array([1.0]), np.array([0]), np.array([0]))
    assert (steps.dt_s.tolist(), steps.dx_m.tolist(), steps.fuel_g.tolist()) == (
        [0.0],
        [0.0],
        [0.0],
    )
