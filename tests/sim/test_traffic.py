"""Simulated INRIX: the wave field behind a real leader, per-minute segment means, the delay."""

from __future__ import annotations

import numpy as np
import pytest

from sim.drives import drive_from_speeds
from sim.traffic import WAVE_SPEED_MPS, inrix_snapshots, segment_bounds, wave_field_speed

C = WAVE_SPEED_MPS  # 4.1667 m/s upstream

# 30 m/s for 100 s (to x = 3000 m), then 10 m/s for 100 s.
STEP_DOWN = drive_from_speeds("step", np.concatenate([np.full(1000, 30.0), np.full(1001, 10.0)]))


def test_the_slow_state_lies_ahead_of_the_leader_before_it_gets_there() -> None:
    # At t = 0 the slowdown the leader meets at t = 100 s, x = 3000 m is c x 100 s = 417 m
    # further downstream (it travels upstream to meet the leader).
    front = 3000.0 + C * 100.0
    speeds = wave_field_speed(STEP_DOWN, np.zeros(2), np.array([front - 20.0, front + 20.0]))
    np.testing.assert_allclose(speeds, [30.0, 10.0])


def test_the_slow_state_moves_upstream_behind_the_leader() -> None:
    # At t = 200 s the front of the slow state is 100 s x c upstream of 3000 m: 2583 m.
    front = 3000.0 - C * 100.0
    speeds = wave_field_speed(STEP_DOWN, np.full(2, 200.0), np.array([front - 30.0, front + 30.0]))
    np.testing.assert_allclose(speeds, [30.0, 10.0])


def test_inrix_minutes_are_segment_means_seen_three_minutes_late() -> None:
    steady = drive_from_speeds("steady", np.full(6001, 20.0))
    bounds = segment_bounds(0.0, 4000.0)
    # 0.5 mile segments: 0, 804.7, ..., the last one stretched to 4000 m
    np.testing.assert_allclose(bounds[:2], [0.0, 804.672])
    assert bounds[-1] == 4000.0
    feed = inrix_snapshots(steady, bounds, -300.0, 540.0)
    assert feed.speed_mps.shape == (15, len(bounds) - 1)
    np.testing.assert_allclose(feed.speed_mps, 20.0)
    # the minute 0-60 s is stamped 60 s and arrives at 240 s
    assert feed.measured_at_s[5] == 60.0
    visible = feed.visible_rows(240.0)
    assert feed.measured_at_s[visible].max() == pytest.approx(60.0)
    assert feed.measured_at_s[feed.visible_rows(239.9)].max() == pytest.approx(0.0)


def test_a_minute_mean_averages_the_wave_passing_through_the_segment() -> None:
    bounds = np.array([2000.0, 3000.0])
    feed = inrix_snapshots(STEP_DOWN, bounds, 0.0, 120.0)
    # minute 0-60 s: the whole segment is upstream of the slow front (3417 -> 3167 m): fast
    assert feed.speed_mps[0, 0] == pytest.approx(30.0)
    # minute 120-180 s: the front crosses 3000 -> 2750 m, so part of the segment is slow
    assert 10.0 < feed.speed_mps[2, 0] < 30.0
