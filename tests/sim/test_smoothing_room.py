"""The room a follower needs to smooth a drive's waves, on speeds worked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.drives import drive_from_speeds
from sim.smoothing_room import (
    cruise_saving_pct,
    envelope_room_m,
    room_to_smooth_m,
    trailing_mean,
)

DT_S = 0.1


def test_trailing_mean_averages_each_full_window() -> None:
    np.testing.assert_allclose(trailing_mean(np.array([1.0, 2.0, 3.0, 6.0]), 2), [1.5, 2.5, 4.5])
    with pytest.raises(ValueError, match="does not fit a drive of 4 steps"):
        trailing_mean(np.ones(4), 5)


def test_a_sine_wave_smoothed_over_its_period_needs_amplitude_times_period_over_pi() -> None:
    """v = 20 + 5 sin(2 pi t / 60): the trailing mean over 60 s is 20, the gap follows
    int 5 sin = 5 x 60 / (2 pi) (1 - cos), so its range is 5 x 60 / pi = 95.5 m."""
    t = np.arange(0.0, 600.0, DT_S)
    speed = 20.0 + 5.0 * np.sin(2.0 * math.pi * t / 60.0)
    assert room_to_smooth_m(speed, DT_S, 60.0) == pytest.approx(5.0 * 60.0 / math.pi, rel=0.01)


def test_a_step_up_opens_the_gap_the_mean_takes_to_catch_up() -> None:
    """20 -> 30 m/s: over the next 10 s the trailing mean rises linearly, the leader pulls away
    by the triangle 10 m/s x 10 s / 2 = 50 m; a constant speed needs no room."""
    speed = np.concatenate((np.full(1000, 20.0), np.full(1000, 30.0)))
    assert room_to_smooth_m(speed, DT_S, 10.0) == pytest.approx(50.0, abs=1.0)
    assert room_to_smooth_m(np.full(2000, 25.0), DT_S, 10.0) == pytest.approx(0.0, abs=1e-9)


def test_the_envelope_leaves_120_m_less_the_gap_a_safe_keeps() -> None:
    """a_safe's equilibrium gap: 8 + v^2 (1/3 - 1/5) / 2 = 8 + v^2 / 15: 34.7 m at 20 m/s,
    so 85.3 m of room; at a standstill the 8 m leave 112 m."""
    assert envelope_room_m(20.0) == pytest.approx(120.0 - 8.0 - 400.0 / 15.0)
    assert envelope_room_m(0.0) == pytest.approx(112.0)
    assert envelope_room_m(45.0) == 0.0  # a_safe's gap beyond 120 m


def test_a_steady_leader_leaves_nothing_to_save_by_cruising() -> None:
    drive = drive_from_speeds("2021-01-01-steady", np.full(3001, 25.0))
    assert cruise_saving_pct(drive) == pytest.approx(0.0, abs=0.05)


def test_a_wavy_leader_leaves_fuel_that_cruising_would_save() -> None:
    """+/-5 m/s waves at 20 m/s: the followers burn fuel accelerating out of every wave, which
    cruising at their mean speed does not, so the saving is positive."""
    t = np.arange(0.0, 300.01, DT_S)
    drive = drive_from_speeds("2021-01-01-wave", 20.0 + 5.0 * np.sin(2.0 * math.pi * t / 60.0))
    assert cruise_saving_pct(drive) > 0.0
