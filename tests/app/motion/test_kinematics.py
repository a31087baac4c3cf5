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


def test_a_trajectorys_acceleration_does_not_depend_on_the_others_in_its_batch() -> None:
    """The window's half in points came from the batch's median step: a 10 Hz document beside
    longer 25 Hz ones was read over 2.5 s, not 1 s, and its fuel depended on its neighbours."""
    ten_hz = np.arange(0.0, 20.0001, 0.1)
    # a wave: speed 15 +/- 5 m/s with a 4 s period
    x_ten = 15 * ten_hz - (5 * 4 / (2 * np.pi)) * np.cos(2 * np.pi * ten_hz / 4)
    alone = trajectory_steps(ten_hz, x_ten, np.array([0]), np.zeros(len(ten_hz), dtype=np.int64))
    twenty_five = np.arange(100.0, 140.0001, 0.04)
    time_s = np.concatenate([twenty_five, ten_hz])
    x_m = np.concatenate([20 * (twenty_five - 100.0), x_ten])
    classes = np.zeros(len(time_s), dtype=np.int64)
    beside = trajectory_steps(time_s, x_m, np.array([0, len(twenty_five)]), classes)
    ours = slice(len(twenty_five), None)
    assert beside.accel_mps2[ours] == pytest.approx(alone.accel_mps2)
    assert beside.fuel_g[ours].sum() == pytest.approx(alone.fuel_g.sum())
    assert beside.accel_mps2[: len(twenty_five)] == pytest.approx(0.0, abs=1e-6)
