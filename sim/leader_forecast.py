"""How well a car can forecast its leader's next seconds from its radar's history and its plan.

    .venv/bin/python -m sim.leader_forecast [--drives DIR]

The foresight probe (`sim.rl.hand_probes foresight`) shows that a smoother told its leader's
mean speed over the next `FORECAST_S` (20 s, the best of its windows) saves 60 % of the optimal
bound, against a fifth of it for the same smoother driving its leader's trailing mean. A causal
controller can only drive a forecast of that mean. This measures the forecast the leader's own
past allows: the change from the leader's speed now to its mean over the next 20 s, regressed
(ridge) on its speeds over the last `HISTORY_S` (60 s, one every `LAG_EVERY_S`), each relative
to its speed now, and on that speed. Fitted on each date fold's training dates (`sim.folds`, two
folds), scored on its held-out dates against persistence (forecast: no change), the forecast a
follower that drives its leader's speed makes, and against the trailing mean the causal smoother
drives. The skill is the share of persistence's squared error the ridge removes. The leader here
is the replayed real drive, the AV's leader in every evaluation.

A second ridge adds what the car holds of the road ahead: the recommended planner's targets
(`sim.recommended`, the plan the fleet gets) at the leader's place and `PLAN_OFFSETS_M` ahead
of it, each less the leader's speed now, from plans made in the loop as `sim.plans` makes them
(simulated INRIX, once a minute) with a car at the leader's place pinging once a second (the
AV right behind it pings nearly the same). What it adds over the history is what today's
plans carry of the forecast.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS
from sim.av import PING_EVERY_STEPS
from sim.drives import STEP_S, Drive, load_drives, shared_data_dir
from sim.folds import date_folds
from sim.plans import SimulatedPlanner
from sim.rl.scores import is_stop_and_go

FloatArray = NDArray[np.float64]

FORECAST_S = 20.0
HISTORY_S = 60.0
LAG_EVERY_S = 2.0
# One forecast per this many seconds of each drive (neighbouring ones are nearly the same).
SAMPLE_EVERY_S = 1.0
# Ridge penalty on the weights ((m/s)^2 per unit weight^2), against lags that move together.
RIDGE = 10.0
# Where the plan is read, ahead of the leader (m).
PLAN_OFFSETS_M = (0.0, 250.0, 500.0, 1000.0)
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


def forecast_steps(
    samples: int, lags: NDArray[np.int64], ahead_steps: int, every_steps: int
) -> NDArray[np.int64]:
    """Every `every_steps`-th step of a drive of `samples` with a full history behind it and a
    full window ahead."""
    return np.arange(int(lags[-1]), samples - ahead_steps, every_steps)


def forecast_rows(
    speed_mps: FloatArray, lags: NDArray[np.int64], ahead_steps: int, every_steps: int
) -> tuple[FloatArray, FloatArray]:
    """(features, change to the mean over the next `ahead_steps`) at `forecast_steps`."""
    speed = np.asarray(speed_mps, dtype=np.float64)
    oldest = int(lags[-1])
    steps = forecast_steps(len(speed), lags, ahead_steps, every_steps)
    if len(steps) == 0:
        return np.empty((0, len(lags) + 1)), np.empty(0)
    running = np.concatenate(([0.0], np.cumsum(speed)))
    future = (running[steps + ahead_steps + 1] - running[steps + 1]) / ahead_steps
    windows = speed[steps[:, None] + np.arange(-oldest, 1)[None, :]]
    return history_features(windows, lags), future - speed[steps]


@dataclass(frozen=True)
class LeaderForecast:
    """Ridge weights on `history_features` rows, then, where `plan_offsets_m` is not empty, the
    plan's targets at the leader's place and those offsets ahead, less the leader's speed now;
    `predict` gives the change to the mean over the window ahead."""

    weights: FloatArray
    lags: NDArray[np.int64]
    plan_offsets_m: tuple[float, ...] = ()

    def predict(self, features: FloatArray) -> FloatArray:
        """Forecast change (m/s) to the leader's mean speed over the window ahead."""
        change: FloatArray = features @ self.weights
        return change

    def mean_ahead(self, past_speeds: FloatArray, plan_targets_mps: Sequence[float] = ()) -> float:
        """The forecast mean speed ahead from one history (oldest first, now last; a shorter
        one is padded with its oldest speed, as if the leader had held it) and, for a forecast
        with the plan, the plan's targets at its offsets from the leader."""
        if len(plan_targets_mps) != len(self.plan_offsets_m):
            raise ValueError(
                f"the forecast reads the plan at {len(self.plan_offsets_m)} places,"
                f" got {len(plan_targets_mps)} targets"
            )
        needed = int(self.lags[-1]) + 1
        history = np.asarray(past_speeds, dtype=np.float64)
        if len(history) < needed:
            history = np.concatenate((np.full(needed - len(history), history[0]), history))
        now = history[-1]
        features = np.concatenate(
            (
                history_features(history[None, -needed:], self.lags)[0],
                np.asarray(plan_targets_mps, dtype=np.float64) - now,
            )
        )
        return float(now + self.predict(features[None, :])[0])


def fit_forecast(
    features: FloatArray,
    change: FloatArray,
    lags: NDArray[np.int64],
    ridge: float = RIDGE,
    plan_offsets_m: Sequence[float] = (),
) -> LeaderForecast:
    """Least squares with a ridge penalty on every weight (closed form)."""
    if len(change) <= features.shape[1]:
        raise ValueError(f"{len(change)} forecasts cannot fit {features.shape[1]} weights")
    gram = features.T @ features + ridge * np.eye(features.shape[1])
    weights = np.linalg.solve(gram, features.T @ change).astype(np.float64)
    return LeaderForecast(weights, lags, tuple(plan_offsets_m))


def plan_ahead(
    drive: Drive,
    steps: NDArray[np.int64],
    offsets_m: Sequence[float],
    planner_params: Mapping[str, Any],
) -> FloatArray:
    """At each of `steps` (ascending), the target of the recommended planner (with
    `planner_params`) at the leader's position plus each offset, less the leader's speed then:
    the plans made as in the loop (`sim.av` pings, then reads its plan), with a car at the
    leader's place pinging once a second."""
    schedule = SimulatedPlanner.for_drive(drive, RECOMMENDED_PLANNER, planner_params)
    position, speed = drive.position_m, drive.speed_mps
    ahead = np.empty((len(steps), len(offsets_m)))
    next_ping = 0
    for row, step in enumerate(steps):
        while next_ping <= step:
            # as in the loop: the ping, then the plan read at the same second, so every plan
            # is made when it is due (from the first second on) with the pings it would have
            schedule.record_ping(
                next_ping * STEP_S,
                position[next_ping],
                speed[next_ping],
                engaged=False,  # the leader is driven by its recorded driver
                lead_present=False,
            )
            schedule.profile(next_ping * STEP_S)
            next_ping += PING_EVERY_STEPS
        profile = schedule.held_profile(float(step) * STEP_S)
        ahead[row] = [profile.at(position[step] + offset) - speed[step] for offset in offsets_m]
    return ahead


def drive_rows(
    drives: Sequence[Drive],
    lags: NDArray[np.int64],
    *,
    with_plan: bool = False,
    planner_params: Mapping[str, Any] = RECOMMENDED_PLANNER_PARAMS,
) -> tuple[FloatArray, FloatArray]:
    """`forecast_rows` of every drive, stacked; with `with_plan`, `plan_ahead` at
    PLAN_OFFSETS_M appended to each row (the plans of `planner_params`, by default the
    fleet's)."""
    ahead = int(round(FORECAST_S / STEP_S))
    every = int(round(SAMPLE_EVERY_S / STEP_S))
    features, changes = [], []
    for drive in drives:
        rows, change = forecast_rows(drive.speed_mps, lags, ahead, every)
        if with_plan:
            steps = forecast_steps(len(drive.speed_mps), lags, ahead, every)
            plan = plan_ahead(drive, steps, PLAN_OFFSETS_M, planner_params)
            rows = np.hstack([rows, plan])
        features.append(rows)
        changes.append(change)
    return np.vstack(features), np.concatenate(changes)


@dataclass(frozen=True)
class ForecastSkill:
    """RMSE (m/s) of the forecast change on held-out drives, by forecaster."""

    fold: int
    group: str
    forecasts: int
    persistence_rmse: float
    trailing_mean_rmse: float
    ridge_rmse: float
    plan_ridge_rmse: float

    def skill_of(self, rmse: float) -> float:
        """Share of persistence's squared error a forecast of this RMSE removes."""
        return 1.0 - (rmse / self.persistence_rmse) ** 2

    @property
    def skill(self) -> float:
        """The history ridge's skill."""
        return self.skill_of(self.ridge_rmse)

    @property
    def plan_skill(self) -> float:
        """The skill of the ridge on the history and the plan."""
        return self.skill_of(self.plan_ridge_rmse)


def held_out_skill(
    drives: Sequence[Drive], folds: int = 2, ridge: float = RIDGE
) -> list[ForecastSkill]:
    """Per date fold and group of its held-out drives: the ridges (history; history and plan)
    fitted on the fold's training dates, persistence, and the trailing mean, scored on the
    held-out dates."""
    lags = lag_steps()
    history_columns = len(lags) + 1
    # the samples of the trailing mean (now and the lags within TRAILING_S; history first)
    trailing_samples = int(np.sum(lags <= int(round(TRAILING_S / STEP_S))))
    rows = {drive.name: drive_rows([drive], lags, with_plan=True) for drive in drives}

    def stacked(chosen: Sequence[Drive]) -> tuple[FloatArray, FloatArray]:
        return (
            np.vstack([rows[drive.name][0] for drive in chosen]),
            np.concatenate([rows[drive.name][1] for drive in chosen]),
        )

    found = []
    for fold in date_folds(drives, folds):
        features, change = stacked(fold.train)
        history = fit_forecast(features[:, :history_columns], change, lags, ridge)
        with_plan = fit_forecast(features, change, lags, ridge, PLAN_OFFSETS_M)
        for group, member in DRIVE_GROUPS.items():
            chosen = [drive for drive in fold.held_out if member(drive)]
            if not chosen:
                continue
            features, change = stacked(chosen)
            # its change from now: the mean of (lagged - now), now's term being 0
            trailing = features[:, : trailing_samples - 1].sum(axis=1) / trailing_samples
            history_error = change - history.predict(features[:, :history_columns])
            found.append(
                ForecastSkill(
                    fold=fold.index,
                    group=group,
                    forecasts=len(change),
                    persistence_rmse=_rmse(change),
                    trailing_mean_rmse=_rmse(change - trailing),
                    ridge_rmse=_rmse(history_error),
                    plan_ridge_rmse=_rmse(change - with_plan.predict(features)),
                )
            )
    return found


def _rmse(error: FloatArray) -> float:
    return float(np.sqrt(np.mean(error**2)))


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
            f" {row.trailing_mean_rmse:.2f}, ridge {row.ridge_rmse:.2f} (skill {row.skill:+.2f}),"
            f" with the plan {row.plan_ridge_rmse:.2f} (skill {row.plan_skill:+.2f})"
        )


if __name__ == "__main__":
    main()
