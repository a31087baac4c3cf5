"""The leader forecast of `sim.leader_forecast`, on speeds worked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS
from sim.drives import STEP_S, drive_from_speeds, load_drive, shared_data_dir
from sim.leader_forecast import (
    PLAN_OFFSETS_M,
    drive_rows,
    fit_forecast,
    forecast_rows,
    forecast_steps,
    held_out_skill,
    history_features,
    lag_steps,
)
from sim.plans import SimulatedPlanner


def test_lags_reach_a_minute_back_every_two_seconds() -> None:
    np.testing.assert_array_equal(lag_steps(), np.arange(0, 601, 20))


def test_rows_pair_each_history_with_the_change_to_the_mean_ahead() -> None:
    """Speeds 1..8, lags 0 and 2 steps, 2 steps ahead: at step 2 the history is 1 (2 back) and
    3 (now), the mean of steps 3-4 is 4.5, so the row is [1 - 3, 1, 3] -> 1.5; rows run to step
    5, the last with two steps ahead (mean of 7 and 8 = 7.5, from 6)."""
    features, change = forecast_rows(np.arange(1.0, 9.0), np.array([0, 2]), 2, 1)
    np.testing.assert_allclose(features[0], [-2.0, 1.0, 3.0])
    np.testing.assert_allclose(change, [1.5, 1.5, 1.5, 1.5])
    assert len(features) == 4
    np.testing.assert_allclose(features[-1], [-2.0, 1.0, 6.0])
    # a drive too short for one history and one window gives no row
    assert forecast_rows(np.ones(3), np.array([0, 2]), 2, 1)[0].shape == (0, 3)


def test_the_fit_recovers_a_linear_law_and_forecasts_from_a_short_history() -> None:
    lags = np.array([0, 2, 4])
    rng = np.random.default_rng(0)
    features = np.hstack([rng.normal(size=(500, 2)), np.ones((500, 1)), rng.normal(size=(500, 1))])
    law = np.array([0.5, -0.25, 1.0, 0.1])
    forecast = fit_forecast(features, features @ law, lags, ridge=1e-9)
    np.testing.assert_allclose(forecast.weights, law, atol=1e-6)
    # history [20, 22] padded to [20, 20, 22]: features [20 - 22, 20 - 22, 1, 22]
    expected = 22.0 + float(np.array([-2.0, -2.0, 1.0, 22.0]) @ law)
    assert forecast.mean_ahead(np.array([20.0, 22.0])) == pytest.approx(expected)
    assert history_features(np.array([[20.0, 20.0, 20.0, 20.0, 22.0]]), lags).shape == (1, 4)
    with pytest.raises(ValueError, match="3 forecasts cannot fit 4 weights"):
        fit_forecast(features[:3], np.zeros(3), lags)


def test_a_regular_wave_is_forecast_far_better_than_persistence_on_another_date() -> None:
    """A 90 s wave of +/-5 m/s around 20 m/s on two dates: a sinusoid is a linear function of
    its own past, so the ridge fitted on one date forecasts the other's next 20 s almost
    exactly, where persistence (no change) and the trailing minute's mean miss by metres per
    second."""
    t = np.arange(0.0, 1200.0, 0.1)
    drives = [
        drive_from_speeds(f"2021-01-0{day}-wave", 20.0 + 5.0 * np.sin(2 * math.pi * t / 90.0 + day))
        for day in (1, 2)
    ]
    rows = [row for row in held_out_skill(drives) if row.group == "all"]
    assert [row.fold for row in rows] == [0, 1]
    for row in rows:
        assert row.persistence_rmse > 2.0
        assert row.trailing_mean_rmse > 2.0
        assert row.ridge_rmse < 0.2
        assert row.skill > 0.99


def test_the_plan_columns_are_the_loops_plan_at_the_leader_and_ahead_of_it() -> None:
    """On the first 8 minutes of a real drive: the history columns are the history-only rows,
    and the plan columns are what a planner fed the leader's pings once a second gives at the
    same step (read here at one step, 5 minutes in, past several plans)."""
    path = next(iter(sorted((shared_data_dir() / "trajectories").glob("*.csv"))))
    drive = load_drive(path).slice(0.0, 480.0)
    lags = lag_steps()
    with_plan, change = drive_rows([drive], lags, with_plan=True)
    history, same_change = drive_rows([drive], lags)
    assert with_plan.shape == (len(history), len(lags) + 1 + len(PLAN_OFFSETS_M))
    np.testing.assert_array_equal(with_plan[:, : len(lags) + 1], history)
    np.testing.assert_array_equal(change, same_change)
    steps = forecast_steps(drive.steps + 1, lags, int(round(20.0 / STEP_S)), 10)
    row = int(np.searchsorted(steps, 3000))
    planner = SimulatedPlanner.for_drive(drive, RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS)
    for ping in range(0, int(steps[row]) + 1, 10):
        planner.record_ping(
            ping * STEP_S,
            drive.position_m[ping],
            drive.speed_mps[ping],
            engaged=False,
            lead_present=False,
        )
        planner.profile(ping * STEP_S)
    profile = planner.profile(float(steps[row]) * STEP_S)
    here = drive.position_m[steps[row]]
    expected = [
        profile.at(here + offset) - drive.speed_mps[steps[row]] for offset in PLAN_OFFSETS_M
    ]
    np.testing.assert_allclose(with_plan[row, len(lags) + 1 :], expected)
