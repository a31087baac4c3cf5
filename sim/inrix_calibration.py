"""Calibrate the simulated INRIX (sim.inrix) on the real INRIX drives and compare the two.

    .venv/bin/python -m sim.inrix_calibration [--data DIR]               # side by side
    .venv/bin/python -m sim.inrix_calibration [--data DIR] --calibrate [--workers N]  # fit

Every drive of `trajectories_with_inrix` is simulated at its real feed's stamps and on its real
segments, so the simulated and the real readings are compared with the same car, second by
second (sim.inrix's statistics). The simulated statistics are the model's, not one draw's: each
drive is simulated REPLICAS times with independent draws of the day's offset and the noise
(replica 0 is the feed the simulator itself gives the planner) and the statistics are taken over
all of them together, as the method of simulated moments averages simulations (with one draw,
nine day offsets of deviation 1.5 m/s move the pooled bias by about 0.5 m/s, several times the
+/-20 % band around the real 0.3 m/s). Replica 0's pooled line is printed too. Each cell reads
`real/simulated`, marked `*` when the simulated statistic is outside +/-20 % of the real one but
within the real one's own standard error, and
`!` when it is outside both. The standard error comes from a block bootstrap of the real errors
(2-minute blocks of a drive, 200 resamples, seed 0): a statistic near zero (a bias, a
correlation) cannot be held to 20 % of itself when the real feed's own value is that uncertain.

`--calibrate` fits the feed model by coordinate descent on a grid, then Nelder-Mead off it
(`refine`), minimising the squared distance, in tolerances, of the pooled statistics and of the
MAE at several shifts of the feed (the shape of the curve the lag is the minimum of) to the real
ones, with a heavy penalty beyond +/-AIM of each. It keeps a whole date out at
a time (two drives of one date saw the same traffic), fits on the other dates and reports the
statistics of the held-out date; then it fits on every drive: those parameters are
`sim.inrix.CALIBRATED`.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from planner import InrixHistory, PlannerParams
from planner.evaluation import DriveErrors, evaluate_drive
from sim.drives import Drive
from sim.folds import drive_date
from sim.inrix import (
    CALIBRATED,
    PROBE_STEP_S,
    STATISTICS,
    ErrorStatistics,
    FeedDraws,
    FeedModel,
    FloatArray,
    PathErrors,
    ProbePairing,
    field_grid,
    mae_curve,
    measured,
    probe_samples,
    segment_series,
    simulated_feed,
    window_means,
)
from sim.plans import simulated_grid
from sim.recorded import RecordedDrive, load_recorded_drives
from sim.traffic import WaveField

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "data" / "trajectories_with_inrix"

# Within +/-20 % of the real feed's statistic (issue 12).
TOLERANCE = 0.2
# The block bootstrap of the real statistics' standard errors.
BOOTSTRAP_BLOCK_S = 120.0
BOOTSTRAP_RESAMPLES = 200
LEGEND = (
    "real/simulated; unmarked: within +/-20 % of the real value; *: outside +/-20 % but within "
    "the real value's standard error; !: outside both"
)
# The planner's TSE variants compared on both feeds (planner/evaluation.py).
TSE_VARIANTS = ("inrix", "predicted", "fused")
# Weight of a statistic's excess beyond AIM x its real value in the fit's loss: staying within
# the tolerance comes before coming closer inside it. The fit aims at +/-15 %, inside the +/-20 %
# tolerance, so that what it reaches holds to 20 % with a margin (a coarse grid step or a
# statistic that moves with another cannot then leave the fit just outside).
OUTSIDE_WEIGHT = 100.0
AIM = 0.15
# Independent draws of each drive's random parts the simulated statistics are taken over.
REPLICAS = 10
# The shifts of the feed (s) whose pooled MAE the fit matches besides the statistics.
CURVE_SHIFTS_S = (-300.0, -150.0, 150.0, 300.0, 600.0)
# The grid each parameter is searched on.
GRID: dict[str, FloatArray] = {
    "field_wave_speed_mps": np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0]),
    "lag_s": np.arange(0.0, 400.0 + 1e-9, 20.0),
    "window_s": np.array([15.0, 30.0, 60.0, 120.0, 180.0, 240.0, 300.0]),
    "reference_speed_mps": np.arange(10.0, 32.0 + 1e-9, 0.5),
    "shrink": np.arange(0.3, 1.2 + 1e-9, 0.1),
    "drive_bias_mps": np.arange(0.0, 4.0 + 1e-9, 0.25),
    "noise_mps": np.arange(0.0, 6.0 + 1e-9, 0.5),
    "noise_correlation": np.arange(0.0, 0.9 + 1e-9, 0.05),
}
# Loss evaluations the off-grid refinement may spend (about 0.6 s each).
REFINE_EVALUATIONS = 400
# The descent is local: it starts once from each of these field wave speeds, the best fit wins.
START_WAVE_SPEEDS_MPS = (1.0, 5.0)
START = FeedModel(
    field_wave_speed_mps=3.0,
    lag_s=150.0,
    window_s=60.0,
    reference_speed_mps=22.0,
    shrink=0.8,
    drive_bias_mps=1.0,
    noise_mps=2.0,
    noise_correlation=0.5,
)
# The longest lag and window on the grid: the field series must reach this far back.
LONGEST_LOOKBACK_S = float(GRID["lag_s"][-1] + GRID["window_s"][-1])


@dataclass(frozen=True)
class CalibrationDrive:
    """One real-INRIX drive with everything a candidate model needs precomputed."""

    recorded: RecordedDrive
    pairing: ProbePairing
    real: PathErrors
    field_times_s: FloatArray
    # The field's segment means per candidate wave speed, `[time, segment]`.
    series: dict[float, FloatArray]
    # The random parts of each replica of the simulated feed (replica 0: the simulator's own).
    draws: tuple[FeedDraws, ...]

    @classmethod
    def of(cls, recorded: RecordedDrive) -> CalibrationDrive:
        """Pair the car with its real feed and sample the field at every candidate wave speed."""
        feed = recorded.feed
        pairing = ProbePairing.along(recorded.drive, feed)
        real = pairing.errors(feed.speed_mps)
        stamps = feed.measured_at_s
        times = field_grid(float(stamps[0]) - LONGEST_LOOKBACK_S, float(stamps[-1]))
        bounds = np.append(feed.segment_start_m, feed.segment_end_m[-1])
        series = {
            float(speed): segment_series(WaveField(recorded.drive, float(speed)), bounds, times)
            for speed in GRID["field_wave_speed_mps"]
        }
        draws = tuple(
            FeedDraws.for_drive(recorded.drive.name, feed.speed_mps.shape, replica)
            for replica in range(REPLICAS)
        )
        return cls(recorded, pairing, real, times, series, draws)

    def simulated(self, model: FeedModel, replicas: int = REPLICAS) -> list[PathErrors]:
        """The simulated feed's errors along the car, one path per replica (the first is the
        readings `simulated_feed` makes when the wave speed is on the grid); each replica
        counts as a drive of its own in the spread of the drives' biases."""
        means = window_means(
            self.field_times_s,
            self.series[model.field_wave_speed_mps],
            self.recorded.feed.measured_at_s,
            model.lag_s,
            model.window_s,
        )
        paths = []
        for replica, draws in enumerate(self.draws[:replicas]):
            path = self.pairing.errors(measured(means, model, draws))
            drive = f"{path.drive}#{replica}"
            paths.append(PathErrors(path.shifts_s, path.errors, path.car_speed_mps, drive))
        return paths


def standard_errors(paths: Sequence[PathErrors], seed: int = 0) -> FloatArray:
    """Bootstrap standard error of each pooled statistic: resample 2-minute blocks of the drives
    (errors a few seconds apart are not independent) with replacement."""
    size = int(round(BOOTSTRAP_BLOCK_S / PROBE_STEP_S))
    blocks = [
        PathErrors(
            path.shifts_s,
            path.errors[:, start : start + size],
            path.car_speed_mps[start : start + size],
            path.drive,
        )
        for path in paths
        for start in range(0, path.errors.shape[1] - size + 1, size)
    ]
    generator = np.random.default_rng(seed)
    resampled = np.array(
        [
            ErrorStatistics.pooled(
                [blocks[index] for index in generator.integers(0, len(blocks), len(blocks))]
            ).values()
            for _ in range(BOOTSTRAP_RESAMPLES)
        ]
    )
    finite = np.isfinite(resampled)
    spread: FloatArray = np.full(resampled.shape[1], np.nan)
    defined = finite.sum(axis=0) >= 2
    spread[defined] = np.nanstd(resampled[:, defined], axis=0)
    return spread


@dataclass(frozen=True)
class Target:
    """The real feed's pooled statistics, their standard errors and its MAE curve."""

    statistics: ErrorStatistics
    standard_error: FloatArray
    curve: FloatArray

    @classmethod
    def of(cls, paths: Sequence[PathErrors]) -> Target:
        """The real errors' target."""
        return cls(ErrorStatistics.pooled(paths), standard_errors(paths), mae_curve(paths))

    def tolerance(self) -> FloatArray:
        """20 % of each real statistic, or its standard error if that is larger."""
        allowed: FloatArray = np.fmax(
            TOLERANCE * np.abs(self.statistics.values()), self.standard_error
        )
        return allowed

    def distance(self, simulated: ErrorStatistics) -> FloatArray:
        """Each statistic's distance in tolerances (<= 1: within; NaN where one is missing)."""
        gap: FloatArray = np.abs(simulated.values() - self.statistics.values()) / self.tolerance()
        return gap

    def strictly_within(self, simulated: ErrorStatistics) -> NDArray[np.bool_]:
        """Each statistic within +/-20 % of the real one, standard error aside."""
        real = self.statistics.values()
        inside: NDArray[np.bool_] = np.abs(simulated.values() - real) <= TOLERANCE * np.abs(real)
        return inside

    def loss(self, simulated: Sequence[PathErrors]) -> float:
        """Squared distances of the statistics and of the MAE at CURVE_SHIFTS_S, summed, plus
        OUTSIDE_WEIGHT x the squared excess of each statistic beyond +/-AIM of the real one
        (a near-zero statistic, a bias or a correlation, is held to a share of itself too, not
        only to its standard error)."""
        pooled = ErrorStatistics.pooled(simulated)
        statistics = self.distance(pooled)
        real = self.statistics.values()
        outside = np.fmax(np.abs(pooled.values() - real) / (AIM * np.abs(real)) - 1.0, 0.0)
        shifts = simulated[0].shifts_s
        at = [int(np.argmin(np.abs(shifts - shift))) for shift in CURVE_SHIFTS_S]
        curve = (mae_curve(simulated)[at] - self.curve[at]) / (TOLERANCE * self.curve[at])
        return float(
            np.nansum(statistics**2) + OUTSIDE_WEIGHT * np.nansum(outside**2) + np.nansum(curve**2)
        )


def simulate_all(
    drives: Sequence[CalibrationDrive], model: FeedModel, replicas: int = REPLICAS
) -> list[PathErrors]:
    """Every replica of every drive's simulated errors."""
    return [path for drive in drives for path in drive.simulated(model, replicas)]


def loss_on(drives: Sequence[CalibrationDrive]) -> Callable[[FeedModel], float]:
    """The fit's loss of a model on `drives`: every replica simulated, against their real feed."""
    target = Target.of([drive.real for drive in drives])

    def cost(model: FeedModel) -> float:
        return target.loss(simulate_all(drives, model))

    return cost


def fit(drives: Sequence[CalibrationDrive], start: FeedModel = START) -> FeedModel:
    """Coordinate descent over GRID from `start` until no single parameter improves the loss."""
    cost = loss_on(drives)
    best, best_cost = start, cost(start)
    improved = True
    while improved:
        improved = False
        for name, values in GRID.items():
            for value in values:
                candidate = replace(best, **{name: float(value)})
                candidate_cost = cost(candidate)
                if candidate_cost < best_cost - 1e-9:
                    best, best_cost, improved = candidate, candidate_cost, True
    return best


def refine(cost: Callable[[FeedModel], float], start: FeedModel) -> FeedModel:
    """Nelder-Mead from the grid's best over every parameter but the wave speed, in units of
    their grid steps, within the grid's range. One parameter at a time stops in narrow valleys
    where the statistics move together (a wider day bias raises the pooled bias and the
    correlation with the spread; only a lower reference speed and correlation together bring
    them back); the simplex moves them at once. Deterministic: the draws are fixed."""
    names = [name for name in GRID if name != "field_wave_speed_mps"]
    step = np.array([float(np.min(np.diff(GRID[name]))) for name in names])
    low = np.array([float(GRID[name][0]) for name in names])
    high = np.array([float(GRID[name][-1]) for name in names])
    origin = np.array([float(getattr(start, name)) for name in names])

    def model_at(units: FloatArray) -> FeedModel:
        values = np.clip(origin + units * step, low, high)
        return replace(start, **{name: float(v) for name, v in zip(names, values, strict=True)})

    result = minimize(
        lambda units: cost(model_at(units)),
        np.zeros(len(names)),
        method="Nelder-Mead",
        options={
            "initial_simplex": np.vstack([np.zeros(len(names)), np.eye(len(names))]),
            "maxfev": REFINE_EVALUATIONS,
            "xatol": 0.05,
            "fatol": 1e-3,
        },
    )
    # a hundredth of a grid step: finer than the statistics tell apart (a tenth can move one by
    # 4 % of its real value)
    tidy = np.round(np.clip(origin + result.x * step, low, high) / (step / 100)) * (step / 100)
    refined = replace(start, **{name: float(v) for name, v in zip(names, tidy, strict=True)})
    return refined if cost(refined) < cost(start) else start


def fit_from_every_wave_speed(drives: Sequence[CalibrationDrive]) -> FeedModel:
    """The best of the descents started at each of START_WAVE_SPEEDS_MPS, refined off the grid."""
    cost = loss_on(drives)
    fits = [
        fit(drives, replace(START, field_wave_speed_mps=float(speed)))
        for speed in START_WAVE_SPEEDS_MPS
    ]
    return refine(cost, min(fits, key=cost))


def format_value(name: str, value: float) -> str:
    """A statistic as printed: seconds whole, speeds and correlations to two decimals."""
    if np.isnan(value):
        return "-"
    return f"{value:.0f}" if name == "lag_s" else f"{value:.2f}"


def side_by_side(label: str, simulated: Sequence[PathErrors], real: Sequence[PathErrors]) -> str:
    """One line: real/simulated per statistic; `*` outside +/-20 % but within the real one's
    standard error, `!` outside both."""
    target = Target.of(real)
    statistics = ErrorStatistics.pooled(simulated)
    distance = target.distance(statistics)
    strict = target.strictly_within(statistics)
    cells = []
    for index, name in enumerate(STATISTICS):
        real_text = format_value(name, target.statistics.values()[index])
        simulated_text = format_value(name, statistics.values()[index])
        mark = "*" if distance[index] <= 1.0 and not strict[index] else " "
        mark = "!" if distance[index] > 1.0 else mark
        cells.append(f"{real_text + '/' + simulated_text + mark:>12s}")
    return f"{label:22s} {target.statistics.samples:5d} " + " ".join(cells)


def standard_error_line(real: Sequence[PathErrors]) -> str:
    """The real pooled statistics' own standard errors beside their 20 % bands, `SE (20 %)`:
    where the SE is the wider, the real value cannot hold the simulated one closer."""
    target = Target.of(real)
    values = target.statistics.values()
    cells = [
        f"{format_value(name, error)} ({format_value(name, TOLERANCE * abs(value))})".rjust(12)
        for name, error, value in zip(STATISTICS, target.standard_error, values, strict=True)
    ]
    return f"{'  real SE (20 % band)':22s} {'':5s} " + " ".join(cells)


def header() -> str:
    """Column names of `side_by_side` lines."""
    short = {
        "mae_mps": "MAE",
        "bias_mps": "bias",
        "lag_s": "lag s",
        "mae_at_lag_mps": "MAE at lag",
        "congested_mae_mps": "queue MAE",
        "congested_bias_mps": "queue bias",
        "freeflow_bias_mps": "open bias",
        "autocorrelation_60s": "autocorr 60s",
        "bias_spread_mps": "bias spread",
    }
    return f"{'real/simulated':22s} {'s':>5s} " + " ".join(
        f"{short[name]:>12s}" for name in STATISTICS
    )


def drive_label(drive: Drive) -> str:
    """`2021-03-08 #0`: the date and the drive's number within the session."""
    number = drive.name.split("masterArray_")[1].split("_")[0]
    return f"{drive_date(drive)} #{number}"


def compare(
    drives: Sequence[CalibrationDrive], model: FeedModel, say: Callable[[str], None]
) -> None:
    """Per drive and pooled, the real against the simulated feed of `model`."""
    say(header())
    real = [drive.real for drive in drives]
    for drive in drives:
        say(side_by_side(drive_label(drive.recorded.drive), drive.simulated(model), [drive.real]))
    say(side_by_side("all drives", simulate_all(drives, model), real))
    say(standard_error_line(real))
    say(side_by_side("  replica 0 alone", simulate_all(drives, model, 1), real))
    say(LEGEND)


def compare_planner(
    drives: Sequence[CalibrationDrive], model: FeedModel, say: Callable[[str], None]
) -> None:
    """Per drive and pooled, the planner's TSE error on the real and on the simulated feed."""
    say("The planner's TSE against the car on each feed (planner/evaluation.py: every 10 s, the")
    say("estimate along the next minute's path vs the car's mean speed), MAE m/s, real/simulated:")
    say(f"{'':22s} {'decisions':>9s} " + " ".join(f"{variant:>13s}" for variant in TSE_VARIANTS))
    found = [planner_errors(drive, model) for drive in drives]
    for drive, errors in zip(drives, found, strict=True):
        cells = [
            tse_cell(
                errors["real"].mean_absolute_error(variant),
                errors["simulated"].mean_absolute_error(variant),
            )
            for variant in TSE_VARIANTS
        ]
        decisions = len(errors["real"].truth_mps)
        say(f"{drive_label(drive.recorded.drive):22s} {decisions:9d} " + " ".join(cells))
    pooled = pooled_planner_mae(found)
    cells = [
        tse_cell(pooled["real"][variant], pooled["simulated"][variant]) for variant in TSE_VARIANTS
    ]
    say(f"{'all drives':22s} {'':9s} " + " ".join(cells))


def pooled_planner_mae(found: Sequence[dict[str, DriveErrors]]) -> dict[str, dict[str, float]]:
    """MAE over every decision of every drive, per feed and TSE variant."""
    return {
        feed: {
            variant: float(
                np.mean(
                    np.concatenate(
                        [
                            np.abs(errors[feed].estimates_mps[variant] - errors[feed].truth_mps)
                            for errors in found
                        ]
                    )
                )
            )
            for variant in TSE_VARIANTS
        }
        for feed in ("real", "simulated")
    }


def tse_cell(real: float, simulated: float) -> str:
    """`real/simulated`, `!` when the simulated is outside +/-20 % of the real."""
    mark = "!" if abs(simulated - real) > TOLERANCE * abs(real) else " "
    return f"{f'{real:.2f}/{simulated:.2f}{mark}':>13s}"


def planner_errors(drive: CalibrationDrive, model: FeedModel) -> dict[str, DriveErrors]:
    """The planner's TSE errors along the car on the real feed and on the simulated one (made at
    the real one's stamps and segments); both stamped on arrival, so no latency is added."""
    recorded = drive.recorded
    real = recorded.feed
    bounds = np.append(real.segment_start_m, real.segment_end_m[-1])
    feeds = {
        "real": real,
        "simulated": simulated_feed(recorded.drive, bounds, real.measured_at_s, model),
    }
    probe = probe_samples(recorded.drive)
    grid = simulated_grid(recorded.drive)
    return {
        name: evaluate_drive(
            probe,
            InrixHistory(feed.measured_at_s, feed.speed_mps, feed.segment_center_x_m),
            grid,
            PlannerParams(),
            latency_s=0.0,
        )
        for name, feed in feeds.items()
    }


def cross_validate(
    drives: Sequence[CalibrationDrive], say: Callable[[str], None], workers: int = 1
) -> FeedModel:
    """Leave one date out: fit on the others, report the held-out date's statistics; returns
    the fit on every drive. The fits (one per date, then every drive) run in `workers`
    processes; each is deterministic, so the figures do not depend on how many."""
    dates = sorted({drive_date(drive.recorded.drive) for drive in drives})
    trainings = [
        [drive for drive in drives if drive_date(drive.recorded.drive) != date] for date in dates
    ]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        models = list(pool.map(fit_from_every_wave_speed, [*trainings, list(drives)]))
    say(header())
    held_out_paths: list[PathErrors] = []
    for date, model in zip(dates, models, strict=False):
        held_out = [drive for drive in drives if drive_date(drive.recorded.drive) == date]
        paths = simulate_all(held_out, model)
        held_out_paths.extend(paths)
        say(side_by_side(f"{date} held out", paths, [drive.real for drive in held_out]))
        say(f"    fitted on the other dates: {parameters(model)}")
    say(side_by_side("every date held out", held_out_paths, [drive.real for drive in drives]))
    say(LEGEND)
    return models[-1]


def parameters(model: FeedModel) -> str:
    """`name=value, ...` of a model."""
    return ", ".join(f"{field.name}={getattr(model, field.name):g}" for field in fields(model))


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="trajectories_with_inrix")
    parser.add_argument("--calibrate", action="store_true", help="cross-validate and fit")
    parser.add_argument("--workers", type=int, default=1, help="processes fitting side by side")
    args = parser.parse_args(argv)
    drives = [CalibrationDrive.of(recorded) for recorded in load_recorded_drives(args.data)]
    say = print  # noqa: T201 (a command-line report)
    if args.calibrate:
        say("Held-out dates (each fitted on the other dates):")
        model = cross_validate(drives, say, args.workers)
        say("Fitted on every drive (sim.inrix.CALIBRATED):")
    else:
        model = CALIBRATED
    say(f"Simulated with {parameters(model)}:")
    compare(drives, model, say)
    say("")
    compare_planner(drives, model, say)


if __name__ == "__main__":
    main()
