"""The fleet-ahead relay diagnostic: the relay's delay, the forecast's inputs, and that the rows
it is fitted on are what the car behind held when it drove."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim.drives import load_drives
from sim.leader_forecast import forecast_steps, lag_steps
from sim.platoon import PlatoonRun
from sim.rl.fleet_ahead import (
    REAR_AV_COLUMN,
    REFERENCE,
    FleetForecast,
    FleetRelay,
    RearAv,
    fleet_features,
    fleet_lags,
    relayed_pings,
    relayed_run,
    run_rows,
)
from vehicle_agent.controllers import Controller


def test_a_ping_is_received_its_latency_after_it_was_sent() -> None:
    relay = FleetRelay(latency_s=2.0)
    for second, speed in enumerate([10.0, 11.0, 12.0, 13.0]):
        relay.record(float(second), speed)
    assert relay.received(1.9).tolist() == []
    assert relay.received(2.0).tolist() == [10.0]
    assert relay.received(4.5).tolist() == [10.0, 11.0, 12.0]
    assert relay.received(100.0).tolist() == [10.0, 11.0, 12.0, 13.0]


def test_fleet_features_read_back_from_the_newest_ping() -> None:
    lags = fleet_lags()
    # the newest ping and one every 2 s for the minute before it
    assert lags.tolist() == list(range(0, 61, 2))
    pings = np.arange(100.0)  # ping k: k m/s, the newest 99
    features = fleet_features(pings, leader_now_mps=50.0)
    assert features[:3].tolist() == [49.0, 47.0, 45.0]
    assert features[-1] == 99.0 - 60.0 - 50.0
    # fewer than a minute received: padded with the oldest; none: the leader's own speed
    short = fleet_features(np.array([20.0, 21.0]), leader_now_mps=20.0)
    assert short[:2].tolist() == [1.0, 0.0]
    assert np.all(short[1:] == 0.0)
    assert np.all(fleet_features(np.array([]), leader_now_mps=20.0) == 0.0)


@pytest.fixture(scope="module")
def run_and_relay(shared_dir: Path) -> tuple[PlatoonRun, FleetRelay]:
    drive = load_drives(shared_dir / "data" / "trajectories")[0].slice(0.0, 150.0)
    relays: list[FleetRelay] = []

    def build(relay: FleetRelay) -> Controller:
        relays.append(relay)
        return REFERENCE.build(relay)

    run = relayed_run(drive, RearAv("rl_accel, relay kept", 2.0, build))
    return run, relays[0]


def test_the_relay_a_run_rebuilds_is_the_one_the_car_behind_held(
    run_and_relay: tuple[PlatoonRun, FleetRelay],
) -> None:
    run, online = run_and_relay
    # the front AV is follower 0, the rear AV follower 24
    assert np.flatnonzero(run.is_av).tolist() == [1, REAR_AV_COLUMN]
    rebuilt = relayed_pings(run, 2.0)
    # the run's last row is its end state, which no step pinged
    assert rebuilt.sent_s[: len(online.sent_s)] == online.sent_s
    assert rebuilt.speed_mps[: len(online.speed_mps)] == online.speed_mps
    assert len(rebuilt.sent_s) == len(online.sent_s) + 1


def test_the_follower_forecasts_from_the_row_the_forecast_was_fitted_on(
    run_and_relay: tuple[PlatoonRun, FleetRelay],
) -> None:
    run, online = run_and_relay
    rows, _ = run_rows(run, with_fleet=True, latency_s=2.0)
    weights = np.asarray(np.random.default_rng(7).normal(size=rows.shape[1]), dtype=np.float64)
    forecast = FleetForecast(weights, lag_steps(), with_fleet=True)
    leader = run.speed_mps[:, REAR_AV_COLUMN - 1]
    steps = forecast_steps(len(leader), lag_steps(), 200, 10)
    for row, step in [(0, int(steps[0])), (len(steps) - 1, int(steps[-1]))]:
        online_mean = forecast.mean_ahead(leader[: step + 1], online.received(step * 0.1))
        assert online_mean == pytest.approx(leader[step] + rows[row] @ weights)
