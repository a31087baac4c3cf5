"""Fuel consumption: the paper's simplified polynomial energy model (sidebar "Vehicle Energy
Models", section "Simplified Energy Models"), vectorised over vehicles and time.

    f(v, a, theta) = max(beta, C(v) + P(v) a + Q(v) a_+^2 + Z(v) theta)      [g/s]

with the coefficients the field team published for a 2019 Toyota RAV4 (CLEAR, energy model
"RAV4_2019", v2.0; see ../shared/reference/energy-model.md). Two details of that published fit
differ from the paper's printed formula and are followed here, because the coefficients were
fitted with them: a_+ = max(a, 0) (not max(-P/2Q, a)), and the floor beta applies only at
speeds v <= v_c (fuel cut at speed: the floor is 0 above v_c).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

# 1 g/s of gasoline is 1.268 gal/h (energy-model.md), so one gram is 1.268 / 3600 gallons.
GALLONS_PER_GRAM_GASOLINE = 1.268 / 3600.0


@dataclass(frozen=True, slots=True)
class FuelModel:
    """Coefficients of the polynomial fuel-rate model (v in m/s, a in m/s^2, grade in rad)."""

    name: str
    c0: float
    c1: float
    c2: float
    c3: float
    p0: float
    p1: float
    p2: float
    q0: float
    q1: float
    z0: float
    z1: float
    beta: float
    fuel_cut_speed_mps: float
    # Feasible acceleration a_max(v) = b1 exp(-b2 v) + b3 of the same fit (engine power limit).
    b1: float
    b2: float
    b3: float
    gallons_per_gram: float = GALLONS_PER_GRAM_GASOLINE

    def fuel_rate_gps(
        self, speed_mps: ArrayLike, accel_mps2: ArrayLike, grade_rad: ArrayLike = 0.0
    ) -> FloatArray:
        """Instantaneous fuel rate in g/s (paper eq. for f(v, a, theta) with the published a_+)."""
        v = np.asarray(speed_mps, dtype=np.float64)
        a = np.asarray(accel_mps2, dtype=np.float64)
        theta = np.asarray(grade_rad, dtype=np.float64)
        cruise = self.c0 + v * (self.c1 + v * (self.c2 + v * self.c3))
        demand = self.p0 + v * (self.p1 + v * self.p2)
        quadratic = self.q0 + self.q1 * v
        grade = self.z0 + self.z1 * v
        a_plus = np.maximum(a, 0.0)
        rate = cruise + demand * a + quadratic * a_plus * a_plus + grade * theta
        floor = np.where(v <= self.fuel_cut_speed_mps, self.beta, 0.0)
        result: FloatArray = np.maximum(rate, floor)
        return result

    def max_accel_mps2(self, speed_mps: ArrayLike) -> FloatArray:
        """The most acceleration the powertrain can give at this speed, b1 exp(-b2 v) + b3."""
        v = np.asarray(speed_mps, dtype=np.float64)
        result: FloatArray = self.b1 * np.exp(-self.b2 * v) + self.b3
        return result


RAV4_2019 = FuelModel(
    name="RAV4_2019",
    c0=0.14631964767035743,
    c1=0.012179045946260292,
    c2=0.0,
    c3=2.7432588728174234e-05,
    p0=0.04553801347643801,
    p1=0.047436831067050676,
    p2=0.0018022443124799303,
    q0=0.0,
    q1=0.02609037187916979,
    z0=1.4940081773441736,
    z1=1.2718495543500672,
    beta=0.013111753095302022,
    fuel_cut_speed_mps=5.98,
    b1=7.1780386096154185,
    b2=0.053537268955100234,
    b3=0.27965662935753677,
)
