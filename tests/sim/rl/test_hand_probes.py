"""The hand-built followers of `sim.rl.hand_probes` are what their labels say."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim.leader_forecast import LeaderForecast
from sim.rl.hand_probes import (
    MARGINS,
    PLAN_AHEAD_MARGINS,
    STOCK_ACC,
    ForecastFollower,
    ForesightFollower,
    LeaderAverageFollower,
    margin_policies,
    stock_acc_policies,
)
from vehicle_agent.controllers import AccelCommand, Observation, TargetProfile
from vehicle_agent.controllers.policy import (
    acc_features,
    accel_features,
    load_policy,
    requested_accel_mps2,
    requested_gap_setting,
    requested_speed_mph,
    requested_time_margin_s,
)


def test_margin_policies_ask_a_constant_request_and_the_labelled_margin(tmp_path: Path) -> None:
    probes = (*MARGINS, *PLAN_AHEAD_MARGINS)
    entries = margin_policies(tmp_path, probes)
    assert [entry.label for entry in entries] == [probe.label for probe in probes]
    for index, probe in enumerate(probes):
        network = load_policy(tmp_path / f"margin_{index}.npz", "accel")
        for rel, plan_ahead in ((-2.0, 25.0), (0.0, 21.0), (1.0, 15.0)):
            features = accel_features(25.0, 25.0, plan_ahead, True, 50.0, rel)
            action = network.action(features)
            assert requested_accel_mps2(action[0]) == pytest.approx(0.58)
            wanted = (
                probe.base_s + probe.per_rel_s * rel + probe.per_plan_ahead_s * (25.0 - plan_ahead)
            )
            expected = float(np.clip(wanted, 0.0, 1.5))
            assert requested_time_margin_s(action[1]) == pytest.approx(expected)


def lead_seen(time_s: float, speed: float, gap: float, rel: float) -> Observation:
    return Observation(
        time_s=time_s,
        speed_mps=speed,
        target_speed_mps=20.0,
        lead_present=True,
        lead_distance_m=gap,
        lead_rel_speed_mps=rel,
    )


def test_the_leader_average_follower_drives_the_leaders_mean_and_closes_when_it_is_lost() -> None:
    follower = LeaderAverageFollower(window_s=2.0, speed_gain=0.2, gap_gain=0.01, headway_s=1.5)
    # 90 m behind a leader at its own 25 m/s, the reference gap 1.5 x 25 = 37.5 m: the pull
    # 0.01 x (90 - 37.5) = +0.525 m/s^2 is the command (a_safe allows more that far back)
    command = follower.step(lead_seen(0.0, 25.0, 90.0, 0.0))
    assert isinstance(command, AccelCommand)
    assert command.accel_mps2 == pytest.approx(0.525)
    # the leader at 27 m/s for the next step: the mean over the window is 26 m/s
    command = follower.step(lead_seen(0.1, 25.0, 90.0, 2.0))
    assert command.accel_mps2 == pytest.approx(0.2 * 1.0 + 0.525)
    # leader lost: 2 m/s above its own speed (the plan's 20 m/s is slower), 0.2 x 2
    lost = follower.step(Observation(time_s=0.2, speed_mps=25.0, target_speed_mps=20.0))
    assert lost.accel_mps2 == pytest.approx(0.4)
    assert not follower.lead_speeds


def test_the_foresight_follower_drives_the_leaders_mean_over_past_present_or_future() -> None:
    # the leader: 20 m/s for 0.3 s, then 30 m/s (a sample per 0.1 s step)
    leader = np.array([20.0, 20.0, 20.0, 30.0, 30.0, 30.0])
    trailing = ForesightFollower(leader, 0.0, 0.2, speed_gain=0.1, gap_gain=0.0, headway_s=1.5)
    centred = ForesightFollower(leader, 0.5, 0.4, speed_gain=0.1, gap_gain=0.0, headway_s=1.5)
    ahead = ForesightFollower(leader, 1.0, 0.2, speed_gain=0.1, gap_gain=0.0, headway_s=1.5)
    # at step 2 (t = 0.2 s), driving 20 m/s: the trailing mean of steps 1-2 is 20 (no request),
    # the centred one of steps 1-4 is 25, the one ahead of steps 3-4 is 30: 0.1 x (mean - 20)
    for follower, expected in ((trailing, 0.0), (centred, 0.5), (ahead, 1.0)):
        command = follower.step(lead_seen(0.2, 20.0, 90.0, 0.0))
        assert command.accel_mps2 == pytest.approx(expected)
    # at the drive's end the window is cut: the last step ahead is the last sample
    assert ahead.step(lead_seen(0.5, 20.0, 90.0, 10.0)).accel_mps2 == pytest.approx(1.0)
    # a_safe still bounds it: 10 m behind a leader 10 m/s slower, it brakes whatever lies ahead
    closing = ForesightFollower(leader, 1.0, 0.2, speed_gain=0.1, gap_gain=0.0, headway_s=1.5)
    assert closing.step(lead_seen(0.2, 30.0, 10.0, -10.0)).accel_mps2 == pytest.approx(-3.0)
    with pytest.raises(ValueError, match="share of the window"):
        ForesightFollower(leader, 1.5, 0.2, speed_gain=0.2, gap_gain=0.0, headway_s=1.5)


def test_the_forecast_follower_drives_the_forecast_from_the_history_its_radar_saw() -> None:
    # lags 0 and 2 steps; weights on (2 steps back - now, 1, now): the leader's mean ahead is
    # forecast as now + 1 + 0.5 x (2 steps back - now)
    forecast = LeaderForecast(np.array([0.5, 1.0, 0.0]), np.array([0, 2]))
    follower = ForecastFollower(forecast, speed_gain=0.1, gap_gain=0.0, headway_s=1.5)
    assert follower.lead_speeds.maxlen == 3
    # one sample: the history is padded with it, so the forecast is 22 + 1 = 23 m/s
    assert follower.step(lead_seen(0.0, 20.0, 90.0, 2.0)).accel_mps2 == pytest.approx(0.3)
    # leader at 22 then 24: 2 steps back it was 22, the forecast 24 + 1 - 1 = 24 m/s
    follower.step(lead_seen(0.1, 20.0, 90.0, 2.0))
    assert follower.step(lead_seen(0.2, 20.0, 90.0, 4.0)).accel_mps2 == pytest.approx(0.4)
    follower.step(Observation(time_s=0.3, speed_mps=20.0, target_speed_mps=20.0))
    assert not follower.lead_speeds


def test_a_forecast_with_the_plan_reads_it_at_the_leaders_place() -> None:
    # weights on (2 steps back - now, 1, now, plan at the leader - now, plan 100 m on - now):
    # the forecast is the plan's mean over the two places
    forecast = LeaderForecast(
        np.array([0.0, 0.0, 0.0, 0.5, 0.5]), np.array([0, 2]), plan_offsets_m=(0.0, 100.0)
    )
    follower = ForecastFollower(forecast, speed_gain=0.1, gap_gain=0.0, headway_s=1.5)
    # the AV at 1000 m, its leader 90 m + a car's length (5 m) ahead at 1095 m; the plan
    # 18 m/s up to 1100 m, 22 m/s from 1150 m: 18 at the leader, 22 100 m on, so the forecast
    # is 20 m/s and the command 0.1 x (20 - 16)
    plan = TargetProfile(
        np.array([0.0, 1100.0, 1150.0, 5000.0]), np.array([18.0, 18.0, 22.0, 22.0])
    )
    seen = Observation(
        time_s=0.0,
        speed_mps=16.0,
        target_speed_mps=18.0,
        position_m=1000.0,
        target=plan,
        lead_present=True,
        lead_distance_m=90.0,
        lead_rel_speed_mps=0.0,
    )
    assert follower.step(seen).accel_mps2 == pytest.approx(0.4)
    with pytest.raises(ValueError, match="needs the plan"):
        follower.step(lead_seen(0.1, 16.0, 90.0, 0.0))
    with pytest.raises(ValueError, match="reads the plan at 2 places, got 1"):
        forecast.mean_ahead(np.array([20.0]), [18.0])


def test_stock_acc_policies_ask_the_ceiling_with_their_gap_bars(tmp_path: Path) -> None:
    entries = stock_acc_policies(tmp_path)
    assert [entry.label for entry in entries] == [label for label, _, _ in STOCK_ACC]
    for index, bars in enumerate((1, 3)):
        network = load_policy(tmp_path / f"stock_acc_{index}.npz", "acc")
        action = network.action(acc_features(20.0, 20.0, 20.0, True, 45.0, 2))
        # the plan's 20 m/s (44.7 mph) + 20 mph: the clip then bounds it to mean + 5 mph
        assert requested_speed_mph(action[0], 20.0 / 0.44704, True) == pytest.approx(
            20.0 / 0.44704 + 20.0
        )
        assert requested_gap_setting(action[1]) == bars
