"""The RAV4 fuel model against values worked by hand from the published coefficients."""

from __future__ import annotations

import numpy as np
import pytest

from sim.energy import GALLONS_PER_GRAM_GASOLINE, RAV4_2019

# C(v) = C0 + C1 v + C3 v^3 (C2 = 0), P(v) = p0 + p1 v + p2 v^2, Q(v) = q1 v (q0 = 0)
# at v = 10 m/s: C = 0.146319648 + 0.121790459 + 0.027432589 = 0.295542696
#                P = 0.045538013 + 0.474368311 + 0.180224431 = 0.700130755
#                Q = 0.260903719
C_10 = 0.295542696
P_10 = 0.700130755
Q_10 = 0.260903719


def test_cruising_burns_the_speed_polynomial() -> None:
    assert RAV4_2019.fuel_rate_gps(10.0, 0.0) == pytest.approx(C_10, abs=1e-8)


def test_idling_burns_c0() -> None:
    assert RAV4_2019.fuel_rate_gps(0.0, 0.0) == pytest.approx(0.14631964767035743)


def test_accelerating_adds_the_linear_and_quadratic_terms() -> None:
    # f(10, 1) = C + P + Q = 1.256577170
    assert RAV4_2019.fuel_rate_gps(10.0, 1.0) == pytest.approx(C_10 + P_10 + Q_10, abs=1e-8)
    # a = 2: C + 2P + 4Q
    assert RAV4_2019.fuel_rate_gps(10.0, 2.0) == pytest.approx(C_10 + 2 * P_10 + 4 * Q_10, abs=1e-8)


def test_braking_has_no_quadratic_term_and_cuts_fuel_above_vc() -> None:
    # f(10, -1) = max(0, C - P) = max(0, -0.405) = 0: above v_c = 5.98 m/s the floor is 0
    assert RAV4_2019.fuel_rate_gps(10.0, -1.0) == 0.0
    # f(10, -0.2) = C - 0.2 P = 0.155516545 (a_+ = 0, so no Q term)
    assert RAV4_2019.fuel_rate_gps(10.0, -0.2) == pytest.approx(C_10 - 0.2 * P_10, abs=1e-8)


def test_braking_at_low_speed_keeps_the_beta_floor() -> None:
    # v = 5 <= v_c: C - P = 0.210644 - 0.327778 < 0, so the floor beta applies
    assert RAV4_2019.fuel_rate_gps(5.0, -1.0) == pytest.approx(0.013111753095302022)


def test_grade_adds_z_times_theta() -> None:
    # Z(10) = z0 + 10 z1 = 14.212503721; theta = 0.01 rad
    assert RAV4_2019.fuel_rate_gps(10.0, 0.0, 0.01) == pytest.approx(C_10 + 0.14212503721, abs=1e-8)


def test_vectorised_over_vehicles_and_time() -> None:
    speeds = np.array([[10.0, 0.0], [10.0, 5.0]])
    accels = np.array([[1.0, 0.0], [-1.0, -1.0]])
    rates = RAV4_2019.fuel_rate_gps(speeds, accels)
    assert rates.shape == (2, 2)
    np.testing.assert_allclose(
        rates, [[C_10 + P_10 + Q_10, 0.146319648], [0.0, 0.013111753]], atol=1e-8
    )


def test_feasible_acceleration_falls_with_speed() -> None:
    # a_max(0) = b1 + b3 = 7.457695; a_max(30) = 7.178039 e^(-1.606118) + 0.279657 = 1.720038
    assert RAV4_2019.max_accel_mps2(0.0) == pytest.approx(7.457695239)
    assert RAV4_2019.max_accel_mps2(30.0) == pytest.approx(1.720038, abs=1e-6)


def test_one_gram_per_second_is_1268_gallons_per_hour() -> None:
    assert GALLONS_PER_GRAM_GASOLINE * 3600 == pytest.approx(1.268)
