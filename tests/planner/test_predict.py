"""Step 1: INRIX resampled to the sub-segments and carried past its latency."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.inputs import InrixHistory
from planner.params import PlannerParams
from planner.predict import PREDICTORS, NoInrixEstimate, oldest_reading_used_s, usable_history
from planner.predict.wave_trend import trend_mps2

CENTERS = np.array([0.0, 1000.0, 2000.0])


def test_latest_interpolates_between_segment_centres() -> None:
    history = InrixHistory([0.0], [[30.0, 10.0, 20.0]], CENTERS)
    at = np.array([-500.0, 500.0, 1250.0, 2500.0])
    predicted = PREDICTORS.get("latest")(history, at, 60.0, PlannerParams())
    # Constant beyond the end centres, linear between them.
    assert predicted.tolist() == pytest.approx([30.0, 20.0, 12.5, 20.0])


def test_wave_trend_carries_the_recent_change_upstream() -> None:
    # Segment 3 slows by 6 m/s a minute; the newest snapshot is 180 s old at now = 300 s.
    history = InrixHistory(
        [0.0, 60.0, 120.0], [[30.0, 30.0, 30.0], [30.0, 30.0, 24.0], [30.0, 30.0, 18.0]], CENTERS
    )
    params = PlannerParams(wave_speed_mps=15 / 3.6, trend_weight=0.5, trend_damping_s=120.0)
    predicted = PREDICTORS.get("wave_trend")(history, CENTERS, 300.0, params)
    # slope -0.1 m/s/s at 2000 m; damped horizon D = 120 (1 - e^-1.5) = 93.224 s;
    # the change seen at x + 750 m is the one arriving at x.
    damped = 120 * (1 - math.exp(-1.5))
    assert predicted[0] == pytest.approx(30.0)  # slope at 750 m is 0
    assert predicted[1] == pytest.approx(30.0 + 0.5 * damped * -0.075)  # slope at 1750 m
    assert predicted[2] == pytest.approx(18.0 + 0.5 * damped * -0.1)  # 13.339


def test_wave_trend_with_one_snapshot_is_the_snapshot() -> None:
    history = InrixHistory([0.0], [[30.0, 10.0, 20.0]], CENTERS)
    predicted = PREDICTORS.get("wave_trend")(history, CENTERS, 200.0, PlannerParams())
    assert predicted.tolist() == [30.0, 10.0, 20.0]


def test_a_missing_reading_keeps_the_segments_previous_speed() -> None:
    history = InrixHistory([0.0, 60.0], [[30.0, 12.0, 20.0], [31.0, np.nan, 21.0]], CENTERS)
    usable = usable_history(history, 90.0, PlannerParams())
    assert usable.speed_mps[-1].tolist() == [31.0, 12.0, 21.0]


def test_a_segment_never_read_takes_its_neighbours_speed() -> None:
    history = InrixHistory([0.0], [[30.0, np.nan, 20.0]], CENTERS)
    assert usable_history(history, 60.0, PlannerParams()).speed_mps[0].tolist() == [
        30.0,
        25.0,
        20.0,
    ]


def test_stale_inrix_is_no_estimate() -> None:
    history = InrixHistory([0.0], [[30.0, 30.0, 30.0]], CENTERS)
    with pytest.raises(NoInrixEstimate, match="newest INRIX is 601 s old"):
        usable_history(history, 601.0, PlannerParams(max_inrix_age_s=600))


def test_snapshots_from_the_future_are_not_used() -> None:
    history = InrixHistory([0.0, 120.0], [[30.0, 30.0, 30.0], [5.0, 5.0, 5.0]], CENTERS)
    assert usable_history(history, 60.0, PlannerParams()).speed_mps.tolist() == [[30.0] * 3]


def test_no_reading_at_all_is_no_estimate() -> None:
    history = InrixHistory([0.0], [[np.nan, np.nan, np.nan]], CENTERS)
    with pytest.raises(NoInrixEstimate, match="no INRIX reading"):
        usable_history(history, 10.0, PlannerParams())


def test_a_reading_is_carried_forward_no_longer_than_inrix_may_be_old() -> None:
    # segment 1 was last read 700 s before now: past max_inrix_age_s (600 s) its slowdown is no
    # longer the road's, and it takes its neighbours' speed instead
    history = InrixHistory([0.0, 500.0], [[30.0, 12.0, 20.0], [31.0, np.nan, 21.0]], CENTERS)
    usable = usable_history(history, 700.0, PlannerParams(max_inrix_age_s=600))
    assert usable.speed_mps[-1].tolist() == [31.0, 26.0, 21.0]
    # at 550 s it was 550 s old and still stood for the segment
    usable = usable_history(history, 550.0, PlannerParams(max_inrix_age_s=600))
    assert usable.speed_mps[-1].tolist() == [31.0, 12.0, 21.0]
    assert usable.readings.tolist() == [[True] * 3, [True, False, True]]


def test_the_oldest_reading_a_plan_stands_on_is_known() -> None:
    """A partial outage: the newest snapshot read one segment, the others stand on readings
    500 s older. The plan said 'INRIX 8 s old' and nothing else (planner audit)."""
    params = PlannerParams(max_inrix_age_s=600)
    history = InrixHistory([0.0, 500.0], [[30.0, 12.0, 20.0], [31.0, np.nan, np.nan]], CENTERS)
    assert oldest_reading_used_s(usable_history(history, 508.0, params), 508.0, params) == 0.0
    # past the limit a reading is interpolated over, not carried, and does not count (segment
    # 1's from 0 s); segment 2's from 500 s is carried
    history = InrixHistory(
        [0.0, 500.0, 650.0],
        [[30.0, 12.0, 20.0], [31.0, np.nan, 21.0], [32.0, np.nan, np.nan]],
        CENTERS,
    )
    usable = usable_history(history, 660.0, params)
    assert oldest_reading_used_s(usable, 660.0, params) == 500.0
    # every segment read in the newest snapshot: its own time
    full = InrixHistory([0.0, 60.0], [[30.0, 12.0, 20.0], [31.0, 13.0, 21.0]], CENTERS)
    assert oldest_reading_used_s(usable_history(full, 70.0, params), 70.0, params) == 60.0


def test_one_fresh_segment_cannot_carry_a_corridor_read_long_ago() -> None:
    # every segment read 890 s before now with a slowdown in the middle; 60 s ago only the first
    history = InrixHistory([0.0, 830.0], [[30.0, 5.0, 30.0], [30.0, np.nan, np.nan]], CENTERS)
    with pytest.raises(NoInrixEstimate, match="INRIX read only 1 of 3 segments in the last 600 s"):
        usable_history(history, 890.0, PlannerParams(max_inrix_age_s=600))
    # half the corridor read is enough (the default share); here 2 of 3
    history = InrixHistory([0.0, 830.0], [[30.0, 5.0, 30.0], [30.0, np.nan, 28.0]], CENTERS)
    assert usable_history(history, 890.0, PlannerParams()).speed_mps[-1].tolist() == [
        30.0,
        29.0,
        28.0,
    ]


def test_the_trend_is_fitted_on_readings_only() -> None:
    # segment 2 is missing from the first two snapshots: filled from its neighbour (30 m/s),
    # then read at a steady 12 m/s. Filled values are no change: it has no trend.
    history = InrixHistory(
        [0.0, 60.0, 120.0],
        [[30.0, 30.0, np.nan], [30.0, 30.0, np.nan], [30.0, 30.0, 12.0]],
        CENTERS,
    )
    usable = usable_history(history, 180.0, PlannerParams())
    assert usable.speed_mps[:, 2].tolist() == [30.0, 30.0, 12.0]
    predicted = PREDICTORS.get("wave_trend")(usable, CENTERS, 180.0, PlannerParams())
    assert predicted.tolist() == [30.0, 30.0, 12.0]
    # read at 0 s and 120 s only (the 60 s reading lost): the slope of those two, -0.05 m/s/s
    history = InrixHistory(
        [0.0, 60.0, 120.0],
        [[30.0, 30.0, 24.0], [30.0, 30.0, np.nan], [30.0, 30.0, 18.0]],
        CENTERS,
    )
    usable = usable_history(history, 120.0, PlannerParams())
    predicted = PREDICTORS.get("wave_trend")(usable, CENTERS, 120.0, PlannerParams())
    assert predicted[2] == pytest.approx(18.0)  # h = 0: no horizon to carry the trend over
    params = PlannerParams(wave_speed_mps=0.0, trend_weight=1.0, trend_damping_s=1e9)
    predicted = PREDICTORS.get("wave_trend")(usable, CENTERS, 180.0, params)
    assert predicted[2] == pytest.approx(18.0 - 0.05 * 60.0, rel=1e-6)


def test_a_lost_reading_is_left_out_of_the_trends_fit() -> None:
    # read 24, (lost), 18, 15 at 0, 60, 120, 180 s: centred times -100, 20, 80 about their
    # mean 100 s, speeds 5, -1, -4 about 19 m/s: slope = (-500 - 20 - 320) / 16,800 = -0.05
    history = InrixHistory(
        [0.0, 60.0, 120.0, 180.0],
        [[30.0, 30.0, 24.0], [30.0, 30.0, np.nan], [30.0, 30.0, 18.0], [30.0, 30.0, 15.0]],
        CENTERS,
    )
    usable = usable_history(history, 180.0, PlannerParams())
    assert trend_mps2(usable, 4).tolist() == pytest.approx([0.0, 0.0, -0.05])


def test_a_recovering_segment_may_reach_the_fastest_speed_of_the_recent_snapshots() -> None:
    # the corridor recovers; the prediction is capped by the fastest speed the recent
    # snapshots read (33 m/s, in the oldest), not by the newest snapshot's (28 m/s)
    history = InrixHistory(
        [0.0, 60.0, 120.0],
        [[33.0, 30.0, 10.0], [28.0, 30.0, 20.0], [25.0, 26.0, 28.0]],
        CENTERS,
    )
    params = PlannerParams(trend_weight=1.0)
    predicted = PREDICTORS.get("wave_trend")(history, CENTERS, 300.0, params)
    assert predicted[1:].tolist() == [33.0, 33.0]
