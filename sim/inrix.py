"""A simulated INRIX feed with the real feed's errors, and the statistics that compare the two.

The planner's wave speed must not build the feed it is graded on (issue 12). The traffic state
here is what the probe drove where it drove it, carried along characteristics at the feed
model's own `field_wave_speed_mps`, a parameter calibrated on the real INRIX minutes
(`sim.inrix_calibration`), not the planner's 15 km/h. Over that field a measurement model makes
the feed as INRIX makes it, with its defects:

- spatial averaging: one reading per segment (about 0.5 mile);
- temporal averaging and lag: the reading stamped T is the mean of the field over
  [T - lag - window, T - lag]; like the recorded files (sim/recorded.py), the stamp is when the
  reading arrives, so the lag is inside the numbers;
- shrinkage toward a reference speed (INRIX reports fewer extremes than a car meets: too fast in
  queues, too slow on an open road): reading = reference + shrink x (mean - reference);
- the day's bias: one offset for the whole drive, normal with deviation `drive_bias_mps` (on the
  real drives INRIX is on average 4 m/s too fast on one day and 3 m/s too slow on another);
- noise: per segment a first-order autoregressive series over the minutes (stationary standard
  deviation `noise_mps`, correlation `noise_correlation` from one minute to the next).

The offset and the noise are drawn from a generator seeded by the drive's name, so every
evaluation of a drive sees the same feed.

The feed is never exact: what it says about the road ahead of the leader is the leader's later
speed carried back at the field's wave speed, blurred over a segment and a window, late, shrunk
and noisy.

The error statistics measure a feed against the probe car the way the calibration does: every
second of the drive, the newest reading stamped at or before that second (shifted by `delta`
for the lag) on the segment the car is in, minus the car's speed.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from planner.evaluation import ProbeDrive
from sim.drives import Drive
from sim.traffic import SAMPLE_SPACING_M, InrixFeed, WaveField

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# The field is averaged every 5 s of a reading's window and every 50 m of its segment.
FIELD_STEP_S = 5.0
# A car's speed is compared with the feed once a second.
PROBE_STEP_S = 1.0
# Feed shifts tried when measuring the lag: 5 minutes early to 10 minutes late, every 10 s.
LAG_SEARCH_S = np.arange(-300.0, 600.0 + 1e-9, 10.0)
# The car is in a queue below 15 m/s (54 km/h) and on an open road at or above 25 m/s (90 km/h):
# the two regimes whose errors have opposite signs on the real feed.
CONGESTED_BELOW_MPS = 15.0
FREEFLOW_FROM_MPS = 25.0
# Error autocorrelation is measured one minute apart (one INRIX period).
AUTOCORRELATION_S = 60.0


class SimulatedFeedError(ValueError):
    """Parameters or a road the simulated feed cannot be made with; the message says which."""


@dataclass(frozen=True)
class FeedModel:
    """Parameters of the simulated feed (values: `CALIBRATED`, found by sim.inrix_calibration)."""

    field_wave_speed_mps: float
    lag_s: float
    window_s: float
    reference_speed_mps: float
    shrink: float
    drive_bias_mps: float
    noise_mps: float
    noise_correlation: float

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not np.isfinite(value) or value < 0:
                raise SimulatedFeedError(f"feed model: {name} = {value} must be finite and >= 0")
        if self.window_s == 0:
            raise SimulatedFeedError(
                "feed model: window_s must be > 0 (a reading averages a window)"
            )
        if self.noise_correlation >= 1:
            raise SimulatedFeedError(
                f"feed model: noise_correlation = {self.noise_correlation} must be < 1"
            )


# Found by `python -m sim.inrix_calibration --calibrate` on the nine real-INRIX drives: the
# method of simulated moments (each drive's random parts drawn REPLICAS times), coordinate
# descent on the grid, then Nelder-Mead off it (docs/simulation.md, "Simulated INRIX").
CALIBRATED = FeedModel(
    field_wave_speed_mps=1.0,
    lag_s=128.2,
    window_s=15.0,
    reference_speed_mps=14.795,
    shrink=0.822,
    drive_bias_mps=1.405,
    noise_mps=3.865,
    noise_correlation=0.065,
)


def drive_seed(name: str) -> int:
    """A seed fixed by the drive's name (CRC-32: the same in every process, unlike hash())."""
    return zlib.crc32(name.encode())


def autoregressive_noise(innovations: FloatArray, sigma: float, correlation: float) -> FloatArray:
    """AR(1) series down axis 0 with stationary deviation sigma: n0 = sigma e0,
    n_m = rho n_(m-1) + sigma sqrt(1 - rho^2) e_m."""
    noise = np.empty_like(innovations)
    noise[0] = sigma * innovations[0]
    scale = sigma * np.sqrt(1.0 - correlation**2)
    for minute in range(1, len(innovations)):
        noise[minute] = correlation * noise[minute - 1] + scale * innovations[minute]
    return noise


def segment_series(field: WaveField, bounds_m: FloatArray, times_s: FloatArray) -> FloatArray:
    """The field's mean over each segment at each time: `[time, segment]` (50 m samples)."""
    lengths = np.diff(bounds_m)
    counts = np.maximum(1, np.round(lengths / SAMPLE_SPACING_M).astype(np.int64))
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    segment = np.repeat(np.arange(len(lengths)), counts)
    rank = np.arange(int(counts.sum())) - first[segment]
    sample_x = bounds_m[segment] + (rank + 0.5) * lengths[segment] / counts[segment]
    speeds = field.speed_mps(times_s[:, None], sample_x[None, :])
    means: FloatArray = np.add.reduceat(speeds, first, axis=1) / counts
    return means


def window_means(
    series_times_s: FloatArray,
    series: FloatArray,
    stamps_s: FloatArray,
    lag_s: float,
    window_s: float,
) -> FloatArray:
    """Mean of each segment's series over (T - lag - window, T - lag] for every stamp T (at
    least the one sample at or before T - lag)."""
    cumulative = np.vstack([np.zeros((1, series.shape[1])), np.cumsum(series, axis=0)])
    high = np.searchsorted(series_times_s, stamps_s - lag_s, side="right")
    low = np.searchsorted(series_times_s, stamps_s - lag_s - window_s, side="right")
    low = np.minimum(low, high - 1).clip(0)
    high = np.maximum(high, low + 1)
    means: FloatArray = (cumulative[high] - cumulative[low]) / (high - low)[:, None]
    return means


@dataclass(frozen=True)
class FeedDraws:
    """The standard normal draws behind one drive's feed: the day's offset, then the noise's."""

    offset: float
    innovations: FloatArray

    @classmethod
    def for_drive(cls, name: str, shape: tuple[int, int], replica: int = 0) -> FeedDraws:
        """The draws of the generator seeded by the drive's name: replica 0 is the feed the
        simulator gives the planner; the calibration averages statistics over more replicas."""
        generator = np.random.default_rng(
            drive_seed(name) if replica == 0 else [drive_seed(name), replica]
        )
        offset = float(generator.standard_normal())
        return cls(offset, generator.standard_normal(shape))


def measured(means: FloatArray, model: FeedModel, draws: FeedDraws) -> FloatArray:
    """What INRIX reports for true segment means: shrunk toward the reference, offset by the
    day's bias, plus AR(1) noise, never negative."""
    shrunk = model.reference_speed_mps + model.shrink * (means - model.reference_speed_mps)
    noise = autoregressive_noise(draws.innovations, model.noise_mps, model.noise_correlation)
    reading: FloatArray = np.maximum(shrunk + model.drive_bias_mps * draws.offset + noise, 0.0)
    return reading


def field_times(stamps_s: FloatArray, model: FeedModel) -> FloatArray:
    """The field samples every reading's window needs."""
    return field_grid(float(stamps_s[0]) - model.lag_s - model.window_s, float(stamps_s[-1]))


def field_grid(first_s: float, last_s: float) -> FloatArray:
    """Multiples of FIELD_STEP_S covering [first_s, last_s]: every window then averages the same
    samples whichever range was asked (the calibration asks a wider one)."""
    start = np.floor(first_s / FIELD_STEP_S)
    times: FloatArray = FIELD_STEP_S * np.arange(start, np.ceil(last_s / FIELD_STEP_S) + 1)
    return times


def simulated_feed(
    drive: Drive, bounds_m: FloatArray, stamps_s: FloatArray, model: FeedModel
) -> InrixFeed:
    """The drive's simulated INRIX readings stamped `stamps_s` on the segments `bounds_m`."""
    for name, values, least in (("segment bounds", bounds_m, 2), ("stamps", stamps_s, 1)):
        array = np.asarray(values, dtype=np.float64)
        if array.ndim != 1 or len(array) < least or not np.all(np.isfinite(array)):
            raise SimulatedFeedError(f"{drive.name}: {name} must be {least}+ finite numbers")
        if np.any(np.diff(array) <= 0):
            raise SimulatedFeedError(f"{drive.name}: {name} must increase strictly")
    field = WaveField(drive, model.field_wave_speed_mps)
    times = field_times(stamps_s, model)
    means = window_means(
        times, segment_series(field, bounds_m, times), stamps_s, model.lag_s, model.window_s
    )
    return InrixFeed(
        segment_start_m=bounds_m[:-1].copy(),
        segment_end_m=bounds_m[1:].copy(),
        measured_at_s=np.asarray(stamps_s, dtype=np.float64).copy(),
        speed_mps=measured(means, model, FeedDraws.for_drive(drive.name, means.shape)),
        latency_s=0.0,
    )


def probe_samples(drive: Drive) -> ProbeDrive:
    """The car once a second (PROBE_STEP_S): time, distance along the drive, speed."""
    every = int(round(PROBE_STEP_S / drive.dt_s))
    time_s = np.arange(0, drive.steps + 1, every, dtype=np.float64) * drive.dt_s
    return ProbeDrive(time_s, drive.position_m[::every], drive.speed_mps[::every])


@dataclass(frozen=True)
class ProbePairing:
    """Which reading the car is compared with every second, for every shift of the feed.

    `flat_index[d, i]` indexes `speed_mps.ravel()` of a feed with the given stamps and segments:
    the newest reading stamped at or before `time_s[i] + shifts_s[d]` on the car's segment;
    `valid[d, i]` is False where there is none (before the first reading, off the segments).
    """

    shifts_s: FloatArray
    time_s: FloatArray
    speed_mps: FloatArray
    flat_index: IntArray
    valid: NDArray[np.bool_]
    drive: str

    @classmethod
    def along(
        cls, drive: Drive, feed: InrixFeed, shifts_s: FloatArray = LAG_SEARCH_S
    ) -> ProbePairing:
        """The car of `drive` against readings stamped and placed like `feed`'s."""
        probe = probe_samples(drive)
        time_s, x_m = probe.time_s, probe.x_m
        segment = np.searchsorted(feed.segment_start_m, x_m, side="right") - 1
        on_road = (segment >= 0) & (x_m < feed.segment_end_m[-1])
        row = np.searchsorted(feed.measured_at_s, time_s[None, :] + shifts_s[:, None], "right") - 1
        valid = on_road[None, :] & (row >= 0)
        segments = feed.speed_mps.shape[1]
        flat = row.clip(0) * segments + segment.clip(0)[None, :]
        return cls(shifts_s, time_s, probe.speed_mps, flat.astype(np.int64), valid, drive.name)

    def errors(self, speed_mps: FloatArray) -> PathErrors:
        """Reading minus the car's speed, `[shift, second]`, NaN where there is no reading."""
        found: FloatArray = np.where(
            self.valid, speed_mps.ravel()[self.flat_index] - self.speed_mps[None, :], np.nan
        )
        return PathErrors(self.shifts_s, found, self.speed_mps, self.drive)


@dataclass(frozen=True)
class PathErrors:
    """One drive's feed errors along the car's path (`ProbePairing.errors`) and its speeds."""

    shifts_s: FloatArray
    errors: FloatArray
    car_speed_mps: FloatArray
    drive: str


STATISTICS = (
    "mae_mps",
    "bias_mps",
    "lag_s",
    "mae_at_lag_mps",
    "congested_mae_mps",
    "congested_bias_mps",
    "freeflow_bias_mps",
    "autocorrelation_60s",
    "bias_spread_mps",
)


@dataclass(frozen=True)
class ErrorStatistics:
    """A feed's errors against the car: MAE and bias as stamped, the shift of the feed that fits
    the car best (the lag) and the MAE there, MAE and bias while the car is in a queue, bias on an
    open road, the correlation of errors one minute apart, and the standard deviation of the
    drives' biases (over two drives or more). NaN where there is no sample."""

    mae_mps: float
    bias_mps: float
    lag_s: float
    mae_at_lag_mps: float
    congested_mae_mps: float
    congested_bias_mps: float
    freeflow_bias_mps: float
    autocorrelation_60s: float
    bias_spread_mps: float
    samples: int

    def values(self) -> FloatArray:
        """The statistics in `STATISTICS` order."""
        return np.array([getattr(self, name) for name in STATISTICS])

    @classmethod
    def pooled(cls, paths: Sequence[PathErrors]) -> ErrorStatistics:
        """Statistics over every second of every drive together."""
        shifts = paths[0].shifts_s
        errors = np.concatenate([path.errors for path in paths], axis=1)
        speed = np.concatenate([path.car_speed_mps for path in paths])
        curve = np.nan_to_num(mae_curve(paths), nan=np.inf)
        best = int(np.argmin(curve))
        stamped = errors[int(np.argmin(np.abs(shifts)))]
        congested = stamped[speed < CONGESTED_BELOW_MPS]
        freeflow = stamped[speed >= FREEFLOW_FROM_MPS]
        return cls(
            mae_mps=_mean(np.abs(stamped)),
            bias_mps=_mean(stamped),
            lag_s=float(shifts[best]) if np.isfinite(curve[best]) else float("nan"),
            mae_at_lag_mps=float(curve[best]) if np.isfinite(curve[best]) else float("nan"),
            congested_mae_mps=_mean(np.abs(congested)),
            congested_bias_mps=_mean(congested),
            freeflow_bias_mps=_mean(freeflow),
            autocorrelation_60s=_autocorrelation(paths, shifts),
            bias_spread_mps=_bias_spread(paths, shifts),
            samples=int(np.sum(~np.isnan(stamped))),
        )


def mae_curve(paths: Sequence[PathErrors]) -> FloatArray:
    """Pooled MAE at every shift of the feed (NaN at a shift without any reading)."""
    absolute = np.abs(np.concatenate([path.errors for path in paths], axis=1))
    counts = np.sum(~np.isnan(absolute), axis=1)
    curve: FloatArray = np.where(
        counts > 0, np.nansum(absolute, axis=1) / np.maximum(counts, 1), np.nan
    )
    return curve


def _mean(values: FloatArray) -> float:
    kept = values[~np.isnan(values)]
    return float(kept.mean()) if len(kept) else float("nan")


def _bias_spread(paths: Sequence[PathErrors], shifts: FloatArray) -> float:
    """Sample standard deviation of the as-stamped bias of each drive (paths of one drive, e.g.
    the blocks of a bootstrap, count together)."""
    stamped = int(np.argmin(np.abs(shifts)))
    drives = sorted({path.drive for path in paths})
    biases = [
        _mean(np.concatenate([path.errors[stamped] for path in paths if path.drive == drive]))
        for drive in drives
    ]
    kept = np.array([bias for bias in biases if not np.isnan(bias)])
    return float(np.std(kept, ddof=1)) if len(kept) >= 2 else float("nan")


def _autocorrelation(paths: Sequence[PathErrors], shifts: FloatArray) -> float:
    """Pearson correlation of the as-stamped errors AUTOCORRELATION_S apart, within each drive."""
    apart = int(round(AUTOCORRELATION_S / PROBE_STEP_S))
    stamped = int(np.argmin(np.abs(shifts)))
    first = np.concatenate([path.errors[stamped, :-apart] for path in paths])
    second = np.concatenate([path.errors[stamped, apart:] for path in paths])
    both = ~np.isnan(first) & ~np.isnan(second)
    if both.sum() < 3 or np.ptp(first[both]) == 0.0 or np.ptp(second[both]) == 0.0:
        return float("nan")  # too few pairs, or a constant error: no correlation to speak of
    return float(np.corrcoef(first[both], second[both])[0, 1])
