"""The gap envelope: hand-worked moments inside and outside it."""

from __future__ import annotations

import numpy as np
import pytest

from contract.controllers import FLEET_TOP_SPEED_MPS
from sim.gaps import GapBounds, gap_kpis, reachable_leader_excess_m


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
    # slow traffic still has a time gap: 2 m at 4 m/s is 0.5 s; below 1 m/s none applies
    assert bounds.under_time_gap(np.array([2.0, 0.5]), np.array([4.0, 0.9])).tolist() == [
        True,
        False,
    ]


def test_gap_kpis_count_seconds() -> None:
    # one AV over 5 steps of 0.1 s: 5 m (outside), 40 m at 30 m/s (fine), 20 m at 30 m/s
    # (time gap 0.67 s), 130 m (outside), 60 m (fine)
    gaps = np.array([[5.0], [40.0], [20.0], [130.0], [60.0]])
    speeds = np.array([[2.0], [30.0], [30.0], [30.0], [30.0]])
    positions = np.cumsum(speeds * 0.1, axis=0)
    kpis = gap_kpis(gaps, speeds, positions, 0.1, GapBounds())
    assert kpis.max_av_gap_m == 130.0
    assert kpis.gap_out_of_bounds_s == pytest.approx(0.2)
    assert kpis.time_gap_violation_s == pytest.approx(0.1)
    assert kpis.within_bounds_share == pytest.approx(0.4)
    # these gaps open by far more than a car held to 30 m/s covers in 0.1 s (3 m), so the
    # reachable leader stays 5 m ahead of the AV: to it the 130 m gap is inside, while the 5 m
    # gap and the short time gap stay outside, judged to the real leader
    reachable = gap_kpis(gaps, speeds, positions, 0.1, GapBounds(), top_speed_mps=30.0)
    assert reachable.within_bounds_share == pytest.approx(0.4)
    assert reachable.within_reachable_bounds_share == pytest.approx(0.6)


def test_reachable_leader_by_hand() -> None:
    # 1 s steps, top speed 30 m/s, the AV at it. The leader pulls away at 35 m/s for two
    # steps, then holds 30, then slows to 25: a car held to 30 m/s falls 5 m behind it per
    # step and closes 5 m per step once it is slower.
    av = np.array([0.0, 30.0, 60.0, 90.0, 120.0])
    leader = np.array([50.0, 85.0, 120.0, 150.0, 175.0])
    excess = reachable_leader_excess_m(leader - av, av, 1.0, 30.0)
    assert excess.tolist() == pytest.approx([0.0, 5.0, 10.0, 10.0, 5.0])
    # a car cutting in at step 3 to 10 m ahead of the AV: the new leader is within reach
    cut_in = np.array([50.0, 85.0, 120.0, 100.0, 128.0])
    excess = reachable_leader_excess_m(cut_in - av, av, 1.0, 30.0)
    assert excess.tolist() == pytest.approx([0.0, 5.0, 10.0, 0.0, 0.0])


def test_reachable_bounds_judge_only_the_upper_bound() -> None:
    # a leader escaping at 40 m/s from 110 m while the AV holds the 30 m/s top speed: 120, 130,
    # 140 m to the leader, all reachable but the first 10 m. Then an AV that drops back from a
    # slow leader: outside either way. And a gap of 5 m: too small whatever the leader did.
    bounds = GapBounds()
    av = np.array([[0.0], [30.0], [60.0], [90.0]])
    gaps = np.array([[110.0], [120.0], [130.0], [140.0]])
    speeds = np.full((4, 1), 30.0)
    kpis = gap_kpis(gaps, speeds, av, 1.0, bounds, top_speed_mps=30.0)
    assert kpis.within_bounds_share == pytest.approx(0.5)
    assert kpis.within_reachable_bounds_share == pytest.approx(1.0)
    slow = np.array([[110.0], [120.0], [130.0], [140.0]])
    dropping = np.array([[0.0], [10.0], [20.0], [30.0]])  # the AV at 10 m/s, leader at 20
    kpis = gap_kpis(slow, np.full((4, 1), 10.0), dropping, 1.0, bounds, top_speed_mps=30.0)
    assert kpis.within_reachable_bounds_share == kpis.within_bounds_share == pytest.approx(0.5)
    close = gap_kpis(
        np.array([[60.0], [5.0]]),
        np.array([[3.0], [3.0]]),
        np.array([[0.0], [3.0]]),
        1.0,
        bounds,
        top_speed_mps=3.0,
    )
    assert close.within_reachable_bounds_share == close.within_bounds_share == 0.5


def test_no_leader_over_the_top_speed_changes_nothing() -> None:
    rng = np.random.default_rng(7)
    dt = 0.1
    leader_speed = rng.uniform(0.0, FLEET_TOP_SPEED_MPS, size=(600, 2))
    av_speed = rng.uniform(0.0, FLEET_TOP_SPEED_MPS, size=(600, 2))
    av = np.cumsum(av_speed * dt, axis=0)
    gaps = 60.0 + np.cumsum((leader_speed - av_speed) * dt, axis=0)
    excess = reachable_leader_excess_m(gaps, av, dt, FLEET_TOP_SPEED_MPS)
    assert np.abs(excess).max() < 1e-9


def test_bad_bounds_are_named() -> None:
    with pytest.raises(ValueError, match="0 <= min < max"):
        GapBounds(min_gap_m=130.0)
    with pytest.raises(ValueError, match="time gap"):
        GapBounds(min_time_gap_s=-1.0)
