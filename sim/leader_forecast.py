"""How well a car can forecast its leader's next seconds from what its radar has seen.

    .venv/bin/python -m sim.leader_forecast [--drives DIR]

The foresight probe (`sim.rl.hand_probes foresight`) shows that a smoother told its leader's
mean speed over the next `FORECAST_S` (20 s) saves 60 % of the optimal bound, against a fifth
of it for the same smoother driving its leader's trailing mean. A causal controller can only
drive a forecast of that mean. This measures the forecast the leader's own past allows: the
change from the leader's speed now to its mean over the next 20 s, regressed (ridge) on its
speeds over the last `HISTORY_S` (60 s, one every `LAG_EVERY_S`), each relative to its speed
now, and on that speed. Fitted on each date fold's training dates (`sim.folds`, two folds),
scored on its held-out dates against persistence (forecast: no change), the forecast a
follower that drives its leader's speed makes, and against the trailing mean the causal
smoother drives. The skill is the share of persistence's squared error the ridge removes.
The leader here is the replayed real drive, the AV's leader in every evaluation.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sim.drives import STEP_S, Drive, load_drives, shared_data_dir
from sim.folds import date_folds
from sim.rl.scores import is_stop_and_go

FloatArray = NDArray[np.float64]

FORECAST_S = 20.0
HISTORY_S = 60.0
LAG_EVERY_S = 2.0
# One forecast per this many seconds of each drive (neighbouring ones are nearly the same).
SAMPLE_EVERY_S = 1.0
# Ridge penalty on the weights ((m/s)^2 per unit weight^2), against lags that move together.
RIDGE = 10.0
# The trailing mean the causal smoother drives (the best of `hand_probes.LEADER_AVERAGES`),
# here from the history's samples (every LAG_EVERY_S, now included).
TRAILING_S = 60.0
# Groups of held-out drives, as `sim.rl.scores` groups them.
DRIVE_GROUPS: dict[str, Callable[[Drive], bool]] = {
    "all": lambda drive: True,
    "shockwave": lambda drive: drive.kind == "shockwave",
    "stop_and_go": is_stop_and_go,
    "freeflow": lambda drive: drive.kind == "freeflow",
}


def lag_steps(history_s: float = HISTORY_S, every_s: float = LAG_EVERY_S) -> NDArray[np.int64]:
    """Steps back of each lag, 0 (now) first."""
    return np.arange(0, int(round(history_s / STEP_S)) + 1, int(round(every_s / STEP_S)))


def history_features(past_speeds: FloatArray, lags: NDArray[np.int64]) -> FloatArray:
    """One row per history (rows of `past_speeds`, oldest first, now last): the speed `lag`
    steps back minus the speed now, for every lag but 0, then 1 and the speed now."""
    now = past_speeds[:, -1:]
    back = past_speeds[:, -1 - lags[1:]] - now
    features: FloatArray = np.hstack([back, np.ones_like(now), now])
    return features


def forecast_rows(
    speed_mps: FloatArray, lags: NDArray[np.int64], ahead_steps: int, every_steps: int
) -> tuple[FloatArray, FloatArray]:
    """(features, change to the mean over the next `ahead_steps`) at every `every_steps`-th step
    with a full history behind it and a full window ahead."""
    speed = np.asarray(speed_mps, dtype=np.float64)
    oldest = int(lags[-1])
    steps = np.arange(oldest, len(speed) - ahead_steps, every_steps)
    if len(steps) == 0:
        return np.empty((0, len(lags) + 1)), np.empty(0)
    running = np.concatenate(([0.0], np.cumsum(speed)))
    future = (running[steps + ahead_steps + 1] - running[steps + 1]) / ahead_steps
    windows = speed[steps[:, None] + np.arange(-oldest, 1)[None, :]]
    return history_features(windows, lags), future - speed[steps]


@dataclass(frozen=True)
class LeaderForecast:
    """Ridge weights on `history_features`; `predict` gives the change to the future mean."""

    weights: FloatArray
    lags: NDArray[np.int64]

    def predict(self, features: FloatArray) -> FloatArray:
        """Forecast change (m/s) to the leader's mean speed over the window ahead."""
        change: FloatArray = features @ self.weights
        return change

    def mean_ahead(self, past_speeds: FloatArray) -> float:
        """The forecast mean speed ahead from one history (oldest first, now last; a shorter
        one is padded with its oldest speed, as if the leader had held it)."""
        needed = int(self.lags[-1]) + 1
        history = np.asarray(past_speeds, dtype=np.float64)
        if len(history) < needed:
            history = np.concatenate((np.full(needed - len(history), history[0]), history))
        features = history_features(history[None, -needed:], self.lags)
        return float(history[-1] + self.predict(features)[0])


def fit_forecast(
    features: FloatArray, change: FloatArray, lags: NDArray[np.int64], ridge: float = RIDGE
) -> LeaderForecast:
    """Least squares with a ridge penalty on every weight (closed form)."""
    if len(change) <= features.shape[1]:
        raise ValueError(f"{len(change)} forecasts cannot fit {features.shape[1]} weights")
    gram = features.T @ features + ridge * np.eye(features.shape[1])
    weights = np.linalg.solve(gram, features.T @ change).astype(np.float64)
    return LeaderForecast(weights, lags)


def drive_rows(drives: Sequence[Drive], lags: NDArray[np.int64]) -> tuple[FloatArray, FloatArray]:
    """`forecast_rows` of every drive, stacked."""
    ahead = int(round(FORECAST_S / STEP_S))
    every = int(round(SAMPLE_EVERY_S / STEP_S))
    rows = [forecast_rows(drive.speed_mps, lags, ahead, every) for drive in drives]
    return np.vstack([x for x, _ in rows]), np.concatenate([y for _, y in rows])


@dataclass(frozen=True)
class ForecastSkill:
    """RMSE (m/s) of the forecast change on held-out drives, by forecaster."""

    fold: int
    group: str
    forecasts: int
    persistence_rmse: float
    trailing_mean_rmse: float
    ridge_rmse: float

    @property
    def skill(self) -> float:
        """Share of persistence's squared error the ridge removes (1 - MSE / MSE_persistence)."""
        return 1.0 - (self.ridge_rmse / self.persistence_rmse) ** 2


def held_out_skill(
    drives: Sequence[Drive], folds: int = 2, ridge: float = RIDGE
) -> list[ForecastSkill]:
    """Per date fold and group of its held-out drives: the ridge fitted on the fold's training
    dates, persistence, and the trailing mean, scored on the held-out dates."""
    lags = lag_steps()
    # the samples of the trailing mean (now and the lags within TRAILING_S; history first)
    trailing_samples = int(np.sum(lags <= int(round(TRAILING_S / STEP_S))))
    found = []
    for fold in date_folds(drives, folds):
        forecast = fit_forecast(*drive_rows(fold.train, lags), lags, ridge)
        for group, member in DRIVE_GROUPS.items():
            chosen = [drive for drive in fold.held_out if member(drive)]
            if not chosen:
                continue
            features, change = drive_rows(chosen, lags)
            # its change from now: the mean of (lagged - now), now's term being 0
            trailing = features[:, : trailing_samples - 1].sum(axis=1) / trailing_samples
            found.append(
                ForecastSkill(
                    fold=fold.index,
                    group=group,
                    forecasts=len(change),
                    persistence_rmse=float(np.sqrt(np.mean(change**2))),
                    trailing_mean_rmse=float(np.sqrt(np.mean((change - trailing) ** 2))),
                    ridge_rmse=float(np.sqrt(np.mean((change - forecast.predict(features)) ** 2))),
                )
            )
    return found


def main(argv: Sequence[str] | None = None) -> None:
    """Print the held-out forecast skill per fold and group."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drives", type=Path, default=None, help="folder of drive CSVs")
    args = parser.parse_args(argv)
    drives = load_drives(args.drives or shared_data_dir() / "trajectories")
    say = print  # noqa: T201 (a command-line report)
    say(
        f"change to the leader's mean over the next {FORECAST_S:g} s, from its last"
        f" {HISTORY_S:g} s (RMSE, m/s, held-out dates)"
    )
    for row in held_out_skill(drives):
        say(
            f"fold {row.fold} {row.group:>11} ({row.forecasts:5d} forecasts): persistence"
            f" {row.persistence_rmse:.2f}, trailing {TRAILING_S:g} s mean"
            f" {row.trailing_mean_rmse:.2f}, ridge {row.ridge_rmse:.2f} (skill {row.skill:+.2f})"
        )


if __name__ == "__main__":
    main()
