"""The fuel-optimal bound: its adjoint gradient, hand-worked leaders, and a slice of a real drive,
every result verified by replaying the trajectory in the real simulator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contract.idm import I24_IDM
from sim.drives import Drive, drive_from_speeds, load_drive
from sim.energy import RAV4_2019
from sim.gaps import GapBounds
from sim.optimum import (
    OptimumSettings,
    ReplayPolicy,
    _platoon_cost_gradient,
    _sweep_inputs,
    best_row,
    centred_mean,
    optimal_trajectory,
    platoon_fuel_g,
)
from sim.platoon import AvObservation, PlatoonRun, platoon_roles, simulate_platoon

SHARED_DRIVES = Path(__file__).resolve().parents[3] / "shared" / "data" / "trajectories"
WAVE_DRIVE = SHARED_DRIVES / "2021-03-08-22-35-14_masterArray_0_5373.csv"
BOUNDS = GapBounds()


def _times(duration_s: float) -> np.ndarray:
    return np.arange(0.0, duration_s + 0.05, 0.1)


@pytest.mark.parametrize(
    "envelope",
    [
        # a tight envelope: the space bounds bind (the 1.05 s time gap never does at 20 m/s)
        GapBounds(min_gap_m=25.0, max_gap_m=35.0),
        # a 2.5 s time gap: its term binds (a sign error in its adjoint passed the first)
        GapBounds(min_gap_m=5.0, max_gap_m=200.0, min_time_gap_s=2.5),
    ],
    ids=["space-bounds", "time-gap"],
)
def test_adjoint_gradient_matches_finite_differences(envelope: GapBounds) -> None:
    """The hand-derived adjoint is the forward sweep's derivative, clips and penalties included."""
    t = _times(40.0)
    drive = drive_from_speeds("dip", 20.0 - 6.0 * np.exp(-(((t - 15.0) / 4.0) ** 2)))
    baseline = simulate_platoon(drive, platoon_roles(6, 0))
    steps = drive.steps
    # end targets out of reach, so the end penalties are active too
    inputs = _sweep_inputs(drive, baseline, envelope, OptimumSettings(), I24_IDM, RAV4_2019)
    end_state = inputs[-1].copy()
    end_state[3] += 50.0  # the followers' end positions fall short
    end_state[4:] = 21.0  # and so do their end speeds
    fixed = (*inputs[:-1], end_state)
    rng = np.random.default_rng(7)
    human = np.diff(baseline.speed_mps[:, 1]) / drive.dt_s
    request = np.clip(human + rng.normal(0.0, 0.3, steps), -2.9, 1.4)
    gradient = np.zeros(steps)
    _platoon_cost_gradient(request, *fixed, 10.0, gradient)

    def objective(values: np.ndarray) -> float:
        fuel, penalty = _platoon_cost_gradient(values, *fixed, 10.0, np.zeros(steps))
        return float(fuel + 10.0 * penalty)

    for step in (0, 50, 150, 300, steps - 1):
        bump = np.zeros(steps)
        bump[step] = 1e-6
        numeric = (objective(request + bump) - objective(request - bump)) / 2e-6
        assert gradient[step] == pytest.approx(numeric, rel=1e-4, abs=1e-4)


def _assert_verified(result_drive: Drive, settings: OptimumSettings | None = None) -> None:
    result = optimal_trajectory(result_drive, humans=8, settings=settings)
    assert result.collisions == 0
    assert result.gap_out_of_bounds_s == 0.0
    assert result.time_gap_violation_s == 0.0
    assert BOUNDS.min_gap_m <= result.min_gap_m <= result.max_gap_m <= BOUNDS.max_gap_m


def test_constant_speed_leader_optimum_is_to_cruise() -> None:
    """Behind a steady leader, with no distance lost, the convex fuel curve makes cruising best."""
    drive = drive_from_speeds("steady", np.full(len(_times(120.0)), 25.0))
    result = optimal_trajectory(drive, humans=8)
    assert abs(result.fuel_saving_pct) < 0.05
    assert abs(result.total_fuel_saving_pct) < 0.05
    # the optimiser stops on a flat valley, not exactly at the cruise: the speed stays near 25
    assert np.abs(result.run.speed_mps[:, 1] - 25.0).max() < 1.0
    assert result.collisions == 0
    assert result.gap_out_of_bounds_s == 0.0


def test_one_slowdown_is_smoothed_within_the_envelope() -> None:
    """A 25 -> 10 -> 25 m/s dip: the AV opens its gap instead of braking, and saves fuel."""
    t = _times(120.0)
    drive = drive_from_speeds("dip", 25.0 - 15.0 * np.exp(-(((t - 40.0) / 8.0) ** 2)))
    result = optimal_trajectory(drive, humans=8)
    baseline = simulate_platoon(drive, platoon_roles(9, 0))
    av_speed = result.run.speed_mps[:, 1]
    assert av_speed.min() > baseline.speed_mps[:, 1].min() + 1.0
    assert result.fuel_saving_pct > 3.0
    assert result.total_fuel_saving_pct > 3.0
    assert result.collisions == 0
    assert result.gap_out_of_bounds_s == 0.0
    assert result.time_gap_violation_s == 0.0
    assert result.max_gap_m <= BOUNDS.max_gap_m
    assert result.min_gap_m >= BOUNDS.min_gap_m
    settings = OptimumSettings()
    assert result.accel_mps2.min() >= settings.min_accel_mps2
    assert result.accel_mps2.max() <= settings.max_accel_mps2
    # the figures are the replay's: recomputing them from its trajectories gives the same
    assert result.fuel_g == pytest.approx(platoon_fuel_g(result.run))
    assert result.baseline_fuel_g == pytest.approx(platoon_fuel_g(baseline))


def test_the_bound_of_several_starts_is_the_best_within_the_envelope() -> None:
    def row(start: float, fuel: float, out_s: float = 0.0, collisions: int = 0) -> dict:
        return {
            "start_smoothing_s": start,
            "fuel_saving_pct": fuel,
            "collisions": collisions,
            "time_gap_violation_s": 0.0,
            "gap_out_of_bounds_s": out_s,
        }

    # the most fuel within the envelope; more fuel with a collision or outside it counts less
    rows = [row(0, 4.0), row(10, 6.0), row(60, 9.0, collisions=1), row(30, 8.0, out_s=2.0)]
    assert best_row(rows)["start_smoothing_s"] == 10
    # a freeflow drive whose every start leaves the envelope in its first seconds: the fewest
    assert best_row([row(0, 0.2, out_s=8.1), row(60, 0.5, out_s=8.1)])["start_smoothing_s"] == 60
    assert best_row([row(0, 0.2, out_s=8.1), row(60, 0.5, out_s=9.0)])["start_smoothing_s"] == 0
    # a tie goes to the first start
    assert best_row([row(0, 1.0), row(60, 1.0)])["start_smoothing_s"] == 0


def test_centred_mean_by_hand() -> None:
    # window 3: each sample with its neighbours; the ends with the one neighbour they have
    np.testing.assert_allclose(
        centred_mean(np.array([0.0, 3.0, 6.0, 0.0]), 3), [1.5, 3.0, 3.0, 3.0]
    )
    np.testing.assert_allclose(centred_mean(np.array([2.0, 4.0]), 1), [2.0, 4.0])


def test_a_smoothed_start_finds_the_dip_smoothed_as_well() -> None:
    """The same dip from the other start: a bound within the envelope, saving fuel."""
    t = _times(120.0)
    drive = drive_from_speeds("dip", 25.0 - 15.0 * np.exp(-(((t - 40.0) / 8.0) ** 2)))
    result = optimal_trajectory(drive, humans=8, settings=OptimumSettings(start_smoothing_s=20.0))
    assert result.fuel_saving_pct > 3.0
    assert result.collisions == 0
    assert result.gap_out_of_bounds_s == 0.0
    assert result.time_gap_violation_s == 0.0


def test_replay_policy_plays_the_accelerations_back() -> None:
    drive = drive_from_speeds("steady", np.full(101, 20.0))
    accel = np.where(np.arange(100) < 50, -0.5, 0.5)
    run = simulate_platoon(drive, platoon_roles(2, 1), [ReplayPolicy(accel, drive.dt_s)])
    np.testing.assert_allclose(np.diff(run.speed_mps[:, 1]) / drive.dt_s, accel, atol=1e-9)


@pytest.mark.slow
def test_real_drive_slice_saves_fuel_within_the_envelope() -> None:
    drive = load_drive(WAVE_DRIVE).slice(100.0, 180.0)
    result = optimal_trajectory(drive)
    assert result.fuel_saving_pct > 0.0
    assert result.collisions == 0
    assert result.gap_out_of_bounds_s == 0.0
    assert result.time_gap_violation_s == 0.0
    assert result.iterations > 0


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("control_interval_s", 0.0),
        ("min_accel_mps2", 0.5),
        ("penalty_weights", ()),
        ("margin_m", -1.0),
        ("max_iterations", 0),
        ("start_smoothing_s", -1.0),
        ("start_smoothing_s", float("nan")),
    ],
)
def test_settings_refuse_what_cannot_be_solved(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        OptimumSettings(**{field: value})  # type: ignore[arg-type]


def test_a_leader_that_never_moves_is_refused_naming_the_drive() -> None:
    """Fuel per distance, the objective, is undefined over no distance (it divided by zero)."""
    with pytest.raises(ValueError, match="standing: the leader never moves"):
        optimal_trajectory(drive_from_speeds("standing", np.zeros(100)))


def test_a_replay_plays_each_steps_own_acceleration_at_the_simulators_times() -> None:
    # the platoon asks at k x 0.1 s, which is not always k tenths in floating point (4.3 / 0.1
    # is 42.99...): truncating replayed step k - 1's acceleration on 22 of the first 400 steps
    replay = ReplayPolicy(np.arange(400.0), 0.1)
    played = [replay.accel_mps2(AvObservation(k * 0.1, 0.0, 20.0, 30.0, 20.0)) for k in range(400)]
    assert played == list(np.arange(400.0))


def test_platoon_fuel_is_each_steps_rate_at_the_speed_it_starts_from() -> None:
    # one car at 10 then 20 m/s (a = 10 m/s^2 over 1 s), f(v, a) at the step's start, x dt
    run = PlatoonRun(
        drive_name="one car",
        dt_s=1.0,
        is_av=np.array([False]),
        position_m=np.array([[0.0], [15.0]]),
        speed_mps=np.array([[10.0], [20.0]]),
        vehicle_length_m=5.0,
        gap_violation_m=0.0,
    )
    expected = float(RAV4_2019.fuel_rate_gps(np.array([10.0]), np.array([10.0]))[0])
    assert platoon_fuel_g(run) == pytest.approx(expected)
    assert expected != pytest.approx(
        float(RAV4_2019.fuel_rate_gps(np.array([20.0]), np.array([10.0]))[0])
    )
