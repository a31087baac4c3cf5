"""The IDM against its formula (paper sidebar "Car-Following Models") with the I-24 parameters."""

from __future__ import annotations

import numpy as np
import pytest

from contract.idm import (
    I24_IDM,
    IdmParams,
    equilibrium_density_per_m,
    equilibrium_gap_m,
    idm_accel,
)


def test_closing_in_on_a_slower_leader() -> None:
    # s* = 2 + 20(1.24) + 20(5) / (2 sqrt(1.3 x 2)) = 26.8 + 31.008684 = 57.808684
    # a = 1.3 [1 - (20/35)^4 - (57.808684/30)^2] = 1.3 [1 - 0.106622 - 3.713160] = -3.665717
    assert idm_accel(I24_IDM, 30.0, 20.0, 15.0) == pytest.approx(-3.665717, abs=1e-6)


def test_pulling_away_leader_does_not_reduce_desired_gap() -> None:
    # v dv < 0: s* = 2 + 24.8 = 26.8
    # a = 1.3 [1 - 0.106622 - (26.8/60)^2] = 1.3 (0.693867) = 0.902027
    assert idm_accel(I24_IDM, 60.0, 20.0, 25.0) == pytest.approx(0.902027, abs=1e-6)


def test_free_road_accelerates_towards_v0() -> None:
    # huge gap: a = 1.3 [1 - (10/35)^4] = 1.3 (1 - 0.006664) = 1.291337
    assert idm_accel(I24_IDM, 1e9, 10.0, 10.0) == pytest.approx(1.291337, abs=1e-6)
    assert idm_accel(I24_IDM, 1e9, 35.0, 35.0) == pytest.approx(0.0, abs=1e-9)


def test_equilibrium_gap_gives_zero_acceleration() -> None:
    speeds = np.array([0.0, 5.0, 15.0, 30.0])
    gaps = equilibrium_gap_m(I24_IDM, speeds)
    # at v = 0 the gap is s0; at 15 m/s (2 + 18.6) / sqrt(1 - (15/35)^4) = 21.169 m
    assert gaps[0] == pytest.approx(2.0)
    assert gaps[2] == pytest.approx(20.6 / np.sqrt(1 - (15 / 35) ** 4))
    np.testing.assert_allclose(idm_accel(I24_IDM, gaps, speeds, speeds), 0.0, atol=1e-12)


def test_per_vehicle_desired_speed() -> None:
    accel = idm_accel(I24_IDM, [1e9, 1e9], [20.0, 20.0], [20.0, 20.0], [35.0, 20.0])
    assert accel[1] == pytest.approx(0.0, abs=1e-9)
    assert accel[0] > 1.0


def test_no_equilibrium_above_the_desired_speed() -> None:
    with pytest.raises(ValueError, match="desired speed"):
        equilibrium_gap_m(I24_IDM, 35.0)


def test_bad_parameters_are_refused() -> None:
    with pytest.raises(ValueError, match="max_accel_mps2"):
        IdmParams(max_accel_mps2=0.0)
    with pytest.raises(ValueError, match="must not be negative"):
        IdmParams(time_gap_s=-1.0)


def test_equilibrium_density_worked_by_hand() -> None:
    # v = 20 m/s: s = (2 + 1.24 x 20) / sqrt(1 - (20/35)^4) = 26.8 / 0.94519 = 28.354 m,
    # k = 1 / (28.354 + 4) = 0.030908 vehicles per metre
    assert float(equilibrium_density_per_m(I24_IDM, 20.0)) == pytest.approx(0.030908, rel=1e-4)
    # at and above v0 the gap is unbounded: no queue
    assert equilibrium_density_per_m(I24_IDM, [35.0, 40.0]).tolist() == [0.0, 0.0]
    with pytest.raises(ValueError, match="must not be negative"):
        equilibrium_density_per_m(I24_IDM, -1.0)


def test_a_gap_at_or_below_zero_brakes_as_hard_as_the_model_can_without_inf_or_nan() -> None:
    # a collision's gap reads as MIN_MODEL_GAP_M (0.01 m): s* = 2 + 10 x 1.24 = 14.4 m, so
    # 1.3 [1 - (10/35)^4 - (14.4 / 0.01)^2] = -2,695,678.7 m/s^2 (bounded later by the tyres)
    expected = 1.3 * (1.0 - (10.0 / 35.0) ** 4 - (14.4 / 0.01) ** 2)
    accel = idm_accel(I24_IDM, np.array([0.0, -3.0]), 10.0, 10.0)
    np.testing.assert_allclose(accel, [expected, expected])
    assert expected == pytest.approx(-2_695_678.7, abs=0.1)
