"""Simulated INRIX with the real feed's errors: the measurement model, the error statistics, and
the calibration on the shared real-INRIX drives."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sim.drives import Drive, drive_from_speeds
from sim.inrix import (
    CALIBRATED,
    STATISTICS,
    ErrorStatistics,
    FeedDraws,
    FeedModel,
    PathErrors,
    ProbePairing,
    SimulatedFeedError,
    autoregressive_noise,
    drive_seed,
    measured,
    segment_series,
    simulated_feed,
    window_means,
)
from sim.inrix_calibration import (
    REPLICAS,
    TSE_VARIANTS,
    CalibrationDrive,
    Target,
    planner_errors,
    pooled_planner_mae,
    simulate_all,
)
from sim.plans import SimulatedPlanner
from sim.recorded import load_recorded_drives
from sim.traffic import InrixFeed, WaveField

INRIX_DRIVES = Path(__file__).resolve().parents[2].parent / "shared/data/trajectories_with_inrix"

# 30 m/s for 100 s (to x = 3000 m), then 10 m/s for 100 s (to 4000 m).
STEP_DOWN = drive_from_speeds("step", np.concatenate([np.full(1000, 30.0), np.full(1001, 10.0)]))
# The feed as the field itself: no wave, no lag, one field sample per reading, no shrink, no noise.
EXACT = FeedModel(
    field_wave_speed_mps=0.0,
    lag_s=0.0,
    window_s=1.0,
    reference_speed_mps=20.0,
    shrink=1.0,
    drive_bias_mps=0.0,
    noise_mps=0.0,
    noise_correlation=0.0,
)


def test_the_noise_is_first_order_autoregressive() -> None:
    # sigma 2, rho 0.6: n0 = 2 x 1 = 2; n1 = 0.6 x 2 + 2 x 0.8 x 1 = 2.8; n2 = 0.6 x 2.8 = 1.68
    noise = autoregressive_noise(np.array([[1.0], [1.0], [0.0]]), 2.0, 0.6)
    np.testing.assert_allclose(noise[:, 0], [2.0, 2.8, 1.68])


def test_the_noise_keeps_its_deviation_and_correlation_over_many_minutes() -> None:
    innovations = np.random.default_rng(1).standard_normal((20000, 1))
    noise = autoregressive_noise(innovations, 3.0, 0.5)[:, 0]
    assert np.std(noise) == pytest.approx(3.0, rel=0.03)
    assert np.corrcoef(noise[:-1], noise[1:])[0, 1] == pytest.approx(0.5, abs=0.03)


def test_a_reading_averages_the_samples_of_its_window_before_the_lag() -> None:
    times = np.array([0.0, 5.0, 10.0, 15.0, 20.0])
    series = np.array([[1.0], [2.0], [3.0], [4.0], [5.0]])
    # stamped 20 s, 5 s late, over 10 s: the samples in (5, 15] s, i.e. 3 and 4
    assert window_means(times, series, np.array([20.0]), 5.0, 10.0)[0, 0] == 3.5
    # a window shorter than the sampling still reads the sample at T - lag
    assert window_means(times, series, np.array([20.0]), 5.0, 1.0)[0, 0] == 4.0


def test_inrix_reports_fewer_extremes_and_never_a_negative_speed() -> None:
    model = replace(EXACT, reference_speed_mps=20.0, shrink=0.5)
    # 20 + 0.5 (10 - 20) = 15 and 20 + 0.5 (30 - 20) = 25
    no_draws = FeedDraws(0.0, np.zeros((1, 2)))
    np.testing.assert_allclose(measured(np.array([[10.0, 30.0]]), model, no_draws), [[15.0, 25.0]])
    noisy = replace(EXACT, noise_mps=1.0)
    assert measured(np.array([[2.0]]), noisy, FeedDraws(0.0, np.array([[-5.0]])))[0, 0] == 0.0


def test_the_days_bias_shifts_every_reading_of_the_drive() -> None:
    # deviation 2 m/s, drawn offset 1.5: +3 m/s everywhere, noise on top
    model = replace(EXACT, drive_bias_mps=2.0, noise_mps=1.0)
    draws = FeedDraws(1.5, np.array([[0.0, 1.0], [0.0, 0.0]]))
    np.testing.assert_allclose(
        measured(np.full((2, 2), 20.0), model, draws), [[23.0, 24.0], [23.0, 23.0]]
    )


def test_a_segment_reading_is_the_mean_of_what_the_probe_drove_in_it() -> None:
    # Wave speed 0: the speed at x is the one the probe drove at x, 30 m/s before 3000 m and
    # 10 m/s after; [2500, 3500] has half its 50 m samples on each side: 20 m/s.
    field = WaveField(STEP_DOWN, 0.0)
    means = segment_series(field, np.array([2000.0, 3000.0, 4000.0, 4500.0]), np.array([0.0]))
    np.testing.assert_allclose(means[0, :2], [30.0, 10.0])
    middle = segment_series(field, np.array([2500.0, 3500.0]), np.array([0.0, 150.0]))
    np.testing.assert_allclose(middle[:, 0], [20.0, 20.0])


def test_with_a_wave_speed_the_slow_state_reaches_a_place_before_the_probe_does() -> None:
    # 2 m/s upstream: the slowdown the probe meets at t = 100 s, x = 3000 m is at 2900 m at 150 s
    field = WaveField(STEP_DOWN, 2.0)
    means = segment_series(field, np.array([2800.0, 2890.0, 2910.0]), np.array([150.0]))
    np.testing.assert_allclose(means[0], [30.0, 10.0])


def test_the_seed_is_the_drive_names_crc32() -> None:
    assert drive_seed("abc") == 0x352441C2


def test_the_simulated_feed_is_the_model_over_the_field_and_reproducible_per_drive() -> None:
    bounds = np.array([2000.0, 3000.0, 4000.0])
    stamps = np.array([60.0, 120.0])
    exact = simulated_feed(STEP_DOWN, bounds, stamps, EXACT)
    np.testing.assert_allclose(exact.speed_mps, [[30.0, 10.0], [30.0, 10.0]])
    assert exact.latency_s == 0.0  # the lag is inside the readings, as in the recorded files
    np.testing.assert_array_equal(exact.measured_at_s, stamps)
    noisy = replace(EXACT, noise_mps=2.0, noise_correlation=0.5)
    first = simulated_feed(STEP_DOWN, bounds, stamps, noisy)
    again = simulated_feed(STEP_DOWN, bounds, stamps, noisy)
    np.testing.assert_array_equal(first.speed_mps, again.speed_mps)
    assert not np.allclose(first.speed_mps, exact.speed_mps)
    renamed = Drive("other", STEP_DOWN.dt_s, 0.0, STEP_DOWN.speed_mps)
    other = simulated_feed(renamed, bounds, stamps, noisy)
    assert not np.allclose(other.speed_mps, first.speed_mps)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"noise_mps": -1.0}, "noise_mps = -1.0 must be finite and >= 0"),
        ({"lag_s": float("nan")}, "lag_s = nan must be finite"),
        ({"window_s": 0.0}, "window_s must be > 0"),
        ({"noise_correlation": 1.0}, "noise_correlation = 1.0 must be < 1"),
    ],
)
def test_a_feed_model_that_cannot_be_refuses_to_be_made(
    change: dict[str, float], message: str
) -> None:
    with pytest.raises(SimulatedFeedError, match=message):
        replace(EXACT, **change)


def test_the_feed_refuses_segments_or_stamps_out_of_order() -> None:
    with pytest.raises(SimulatedFeedError, match="step: segment bounds must increase strictly"):
        simulated_feed(STEP_DOWN, np.array([0.0, 800.0, 700.0]), np.array([60.0]), EXACT)
    with pytest.raises(SimulatedFeedError, match="step: stamps must be 1\\+ finite numbers"):
        simulated_feed(STEP_DOWN, np.array([0.0, 800.0]), np.array([]), EXACT)


def test_the_car_is_compared_with_the_newest_reading_on_its_segment() -> None:
    car = drive_from_speeds("steady", np.full(2001, 20.0))  # 20 m/s for 200 s
    feed = InrixFeed(
        segment_start_m=np.array([0.0, 2000.0]),
        segment_end_m=np.array([2000.0, 4000.0]),
        measured_at_s=np.array([0.0, 60.0, 120.0, 180.0]),
        # reading of row r, segment s: 10 r + s
        speed_mps=np.array([[0.0, 1.0], [10.0, 11.0], [20.0, 21.0], [30.0, 31.0]]),
        latency_s=0.0,
    )
    pairing = ProbePairing.along(car, feed, np.array([-60.0, 0.0, 60.0]))
    errors = pairing.errors(feed.speed_mps).errors
    # t = 70 s: x = 1400 m (segment 0), newest reading stamped 60 s: 10 - 20
    assert errors[1, 70] == -10.0
    # t = 110 s: x = 2200 m (segment 1): 11 - 20; a minute later's reading: 21 - 20
    assert errors[1, 110] == -9.0
    assert errors[2, 110] == 1.0
    # t = 30 s shifted a minute early: no reading yet
    assert np.isnan(errors[0, 30])


def path(errors_by_shift: list[list[float]], speeds: list[float], drive: str = "a") -> PathErrors:
    return PathErrors(
        np.array([-10.0, 0.0, 10.0]), np.array(errors_by_shift), np.array(speeds), drive
    )


def test_statistics_of_a_hand_made_path() -> None:
    # 60 s in a queue (10 m/s, as stamped +4), 60 s on an open road (30 m/s, -2); shifted 10 s
    # later the readings fit within 1 m/s: lag 10 s.
    speeds = [10.0] * 60 + [30.0] * 60
    stamped = [4.0] * 60 + [-2.0] * 60
    statistics = ErrorStatistics.pooled(
        [path([[6.0] * 120, stamped, [1.0] * 60 + [-1.0] * 60], speeds)]
    )
    assert statistics.mae_mps == 3.0
    assert statistics.bias_mps == 1.0
    assert statistics.lag_s == 10.0
    assert statistics.mae_at_lag_mps == 1.0
    assert statistics.congested_mae_mps == 4.0
    assert statistics.congested_bias_mps == 4.0
    assert statistics.freeflow_bias_mps == -2.0
    assert statistics.samples == 120
    assert np.isnan(statistics.bias_spread_mps)  # one drive


def test_the_bias_spread_is_the_deviation_of_the_drives_biases() -> None:
    # biases +3 and -1 (drive b in two pieces): sample deviation sqrt(8) = 2.83
    first = path([[3.0] * 10] * 3, [20.0] * 10, "a")
    second = path([[-1.0] * 10] * 3, [20.0] * 10, "b")
    third = path([[-1.0] * 5] * 3, [20.0] * 5, "b")
    statistics = ErrorStatistics.pooled([first, second, third])
    assert statistics.bias_spread_mps == pytest.approx(np.sqrt(8.0))


def test_error_autocorrelation_one_minute_apart() -> None:
    rising = [float(second) for second in range(180)]
    assert ErrorStatistics.pooled(
        [path([rising, rising, rising], [20.0] * 180)]
    ).autocorrelation_60s == pytest.approx(1.0)
    # the sign flips every minute: errors a minute apart are opposite
    flipping = [1.0 if (second // 60) % 2 == 0 else -1.0 for second in range(180)]
    flipping[0] = 1.5  # not constant within a minute, so the correlation is defined
    assert ErrorStatistics.pooled(
        [path([flipping, flipping, flipping], [20.0] * 180)]
    ).autocorrelation_60s == pytest.approx(-1.0, abs=0.02)


def test_a_drive_that_never_queues_has_no_queue_statistics() -> None:
    statistics = ErrorStatistics.pooled([path([[1.0] * 70] * 3, [30.0] * 70)])
    assert np.isnan(statistics.congested_mae_mps)
    assert statistics.freeflow_bias_mps == 1.0


def test_the_simulated_planner_reads_the_calibrated_feed_seeded_by_the_drive() -> None:
    steady = drive_from_speeds("steady", np.full(3001, 25.0))  # 7.5 km in 300 s
    feed = SimulatedPlanner.for_drive(steady, "kernel_smooth").feed
    again = SimulatedPlanner.for_drive(steady, "kernel_smooth").feed
    np.testing.assert_array_equal(feed.speed_mps, again.speed_mps)
    # a reading a minute per 0.5 mile segment, over the road from 3 km before the drive to 3 km
    # past its end, from the planner's history window before the drive (900 s) to its end
    np.testing.assert_allclose(np.diff(feed.measured_at_s), 60.0)
    assert feed.measured_at_s[0] <= -900.0
    assert feed.measured_at_s[-1] == 300.0
    np.testing.assert_allclose((feed.segment_end_m - feed.segment_start_m)[:-1], 804.672)
    assert feed.segment_start_m[0] == -3000.0
    assert feed.segment_end_m[-1] == pytest.approx(10500.0)
    # not the traffic itself: the readings carry the real feed's errors
    assert np.abs(feed.speed_mps - 25.0).mean() > 0.5


@pytest.fixture(scope="module")
def calibration_drives() -> list[CalibrationDrive]:
    return [CalibrationDrive.of(recorded) for recorded in load_recorded_drives(INRIX_DRIVES)]


@pytest.mark.slow
def test_the_calibrated_feed_has_the_real_feeds_error_statistics_within_20_percent(
    calibration_drives: list[CalibrationDrive],
) -> None:
    # the model's statistics (every drive simulated REPLICAS times: its day offsets and noise
    # averaged out, not one draw's luck) each within 20 % of the real feed's, pooled
    target = Target.of([drive.real for drive in calibration_drives])
    simulated = ErrorStatistics.pooled(simulate_all(calibration_drives, CALIBRATED))
    assert REPLICAS * target.statistics.samples == simulated.samples > 50000
    within = dict(zip(STATISTICS, target.strictly_within(simulated), strict=True))
    assert all(within.values()), f"real {target.statistics}, simulated {simulated}"


def test_the_calibration_scores_the_feed_the_simulator_uses(
    calibration_drives: list[CalibrationDrive],
) -> None:
    drive = calibration_drives[2]
    real = drive.recorded.feed
    bounds = np.append(real.segment_start_m, real.segment_end_m[-1])
    feed = simulated_feed(drive.recorded.drive, bounds, real.measured_at_s, CALIBRATED)
    np.testing.assert_allclose(
        drive.pairing.errors(feed.speed_mps).errors,
        drive.simulated(CALIBRATED)[0].errors,
        atol=1e-9,
    )


@pytest.mark.slow
def test_the_planner_errs_on_the_simulated_feed_as_on_the_real_one(
    calibration_drives: list[CalibrationDrive],
) -> None:
    # the prediction stage is no longer graded against its own assumption: on the simulated feed
    # its TSE is as far from the car as on the real feed (pooled MAE within 20 %)
    pooled = pooled_planner_mae([planner_errors(drive, CALIBRATED) for drive in calibration_drives])
    for variant in TSE_VARIANTS:
        assert pooled["simulated"][variant] == pytest.approx(pooled["real"][variant], rel=0.2)
