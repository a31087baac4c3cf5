"""The wave field behind a real leader; the INRIX feed's segments and delay."""

from __future__ import annotations

import numpy as np

from contract.units import WAVE_SPEED_MPS
from sim.drives import drive_from_speeds
from sim.traffic import InrixFeed, segment_bounds, wave_field_speed

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


def test_inrix_segments_are_half_a_mile_and_rows_visible_after_their_latency() -> None:
    bounds = segment_bounds(0.0, 4000.0)
    # 0.5 mile segments: 0, 804.7, ..., the last one stretched to 4000 m
    np.testing.assert_allclose(bounds[:2], [0.0, 804.672])
    assert bounds[-1] == 4000.0
    assert len(bounds) == 5
    feed = InrixFeed(
        segment_start_m=bounds[:-1],
        segment_end_m=bounds[1:],
        measured_at_s=np.array([0.0, 60.0, 120.0]),
        speed_mps=np.full((3, 4), 20.0),
        latency_s=180.0,
    )
    # the reading stamped 60 s arrives at 240 s
    assert feed.measured_at_s[feed.visible_rows(240.0)].max() == 60.0
    assert feed.measured_at_s[feed.visible_rows(239.9)].max() == 0.0
