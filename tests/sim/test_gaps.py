"""The gap envelope: hand-worked moments inside and outside it."""

from __future__ import annotations

import numpy as np
import pytest

from sim.gaps import GapBounds, gap_kpis


def test_defaults_are_the_field_teams_envelope() -> None:
    bounds = GapBounds()
    assert (bounds.min_gap_m, bounds.max_gap_m, bounds.min_time_gap_s) == (7.0, 120.0, 1.0)


def test_space_bounds_and_time_gap() -> None:
    bounds = GapBounds()
    gaps = np.array([5.0, 7.0, 25.0, 120.0, 130.0])
    speeds = np.array([0.0, 5.0, 30.0, 30.0, 30.0])
    assert bounds.outside_space_bounds(gaps).tolist() == [True, False, False, False, True]
    # 25 m at 30 m/s is 0.83 s: under the 1 s time gap; at standstill no time gap applies
    assert bounds.under_time_gap(gaps, speeds).tolist() == [False, False, True, False, False]


def test_gap_kpis_count_seconds() -> None:
    # one AV over 5 steps of 0.1 s: 5 m (outside), 40 m at 30 m/s (fine), 20 m at 30 m/s
    # (time gap 0.67 s), 130 m (outside), 60 m (fine)
    gaps = np.array([[5.0], [40.0], [20.0], [130.0], [60.0]])
    speeds = np.array([[2.0], [30.0], [30.0], [30.0], [30.0]])
    kpis = gap_kpis(gaps, speeds, 0.1, GapBounds())
    assert kpis.max_av_gap_m == 130.0
    assert kpis.gap_out_of_bounds_s == pytest.approx(0.2)
    assert kpis.time_gap_violation_s == pytest.approx(0.1)
    assert kpis.within_bounds_share == pytest.approx(0.4)


def test_bad_bounds_are_named() -> None:
    with pytest.raises(ValueError, match="0 <= min < max"):
        GapBounds(min_gap_m=130.0)
    with pytest.raises(ValueError, match="time gap"):
        GapBounds(min_time_gap_s=-1.0)
