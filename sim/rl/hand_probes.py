"""Hand-built `accel` followers, scored as the pipeline scores, on fold 0's training dates only.

    .venv/bin/python -m sim.rl.hand_probes margin
    .venv/bin/python -m sim.rl.hand_probes plan-ahead
    .venv/bin/python -m sim.rl.hand_probes leader-average
    .venv/bin/python -m sim.rl.hand_probes stock-acc [--files DIR]
    .venv/bin/python -m sim.rl.hand_probes foresight
    .venv/bin/python -m sim.rl.hand_probes forecast

What an action space or a simple causal law can express, before asking PPO to find it: one AV
behind the leader and 24 humans, `kernel_smooth` as in training (`sim.rl.scores`), fold 0's
training dates (`sim.folds`, two folds), so the shipped policy's held-out dates stay unread.
A diagnostic, not a result: nothing here is chosen, and nothing shipped comes from it.

- `margin`: one-layer policy files of the `request_time_margin` action. The request is a
  constant +0.58 m/s^2 (the shipped rl_accel's mean request), the margin fixed at 0, 0.75 or
  1.5 s, or 0.75 s + 0.25 (or 0.125) s per m/s of the leader's relative speed, so it shrinks as
  the leader closes in and grows as it pulls away.
- `plan-ahead`: the same files with a margin that grows with how much faster the AV drives
  than the plan's target 500 m ahead: the plan's foresight, the only foresight the car has.
- `leader-average`: `LeaderAverageFollower`, the simplest causal smoother: it drives toward its
  leader's trailing mean speed over a window, pulled weakly toward a reference gap, under a_safe
  like rl_accel (`rl_accel.bounded_request`), and closes up to a leader it lost.
- `stock-acc`: one-layer `acc` policy files that always ask for the clip's ceiling (the plan's
  target + 20 mph, which the clip bounds to the last second's mean + 5 mph) with 1 or 3 gap
  bars: the car's own ACC following its leader, what any `acc` policy drives through.
- `foresight`: `ForesightFollower`, the leader-average follower told its leader's speeds to
  come (an oracle no car has): it drives the leader's mean over a window that ends now, is
  centred on now, or starts now. Measures how much of the optimal bound perfect foresight of
  the leader gives a simple smoother inside the envelope, so how much the missing foresight
  is worth to a causal one.
- `forecast`: `ForecastFollower`, the same smoother driving a causal forecast of that mean over
  the next 20 s, from the leader's last 60 s as its radar saw them, and from that and the plan
  ahead of the leader (`sim.leader_forecast`'s two ridges, on the plans these runs hold).
  Each forecast is fitted on half of fold 0's training dates and run on the other half, and
  the other way round (the dates dealt as `sim.folds` deals them), so no drive is scored by a
  forecast fitted on its own date.
"""

from __future__ import annotations

import argparse
import tempfile
from abc import abstractmethod
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sim.drives import STEP_S, Drive, load_drives, shared_data_dir
from sim.folds import date_folds
from sim.leader_forecast import (
    FORECAST_S,
    PLAN_OFFSETS_M,
    LeaderForecast,
    drive_rows,
    fit_forecast,
    lag_steps,
)
from sim.platoon import VEHICLE_LENGTH_M
from sim.rl.env import DEFAULT_PLANNER_PARAMS
from sim.rl.scores import ControllerUnderTest, score_drives, summarise
from vehicle_agent.controllers import AccelCommand, Controller, Observation
from vehicle_agent.controllers.microaccel import LeadAccelEstimator
from vehicle_agent.controllers.policy import (
    ACC_FEATURES,
    ACCEL_ACTION_MAX_MPS2,
    ACCEL_FEATURES,
    REL_SPEED_SCALE_MPS,
    SPEED_SCALE_MPS,
    TIME_MARGIN_MAX_S,
    save_policy,
)
from vehicle_agent.controllers.rl_accel import SAFETY, bounded_request

FloatArray = NDArray[np.float64]

# The shipped rl_accel's mean request on fold 0's training dates (sim.rl.diagnose).
CONSTANT_REQUEST_MPS2 = 0.58
# With no leader measured, a leader-average follower asks this much above its speed (m/s).
CLOSING_MPS = 2.0
# Its reference gap, headway x v, stays within these (m): inside the envelope's 7-120 m.
REFERENCE_GAP_MIN_M = 20.0
REFERENCE_GAP_MAX_M = 100.0
# Indices in `accel_features` (each divided by its scale): ego speed, the plan's target 500 m
# ahead, lead - ego speed.
SPEED_FEATURE = 0
PLAN_AHEAD_FEATURE = 2
REL_SPEED_FEATURE = 5


@dataclass(frozen=True)
class MarginProbe:
    """A margin policy: h = base_s + per_rel_s x (lead - ego speed) + per_plan_ahead_s x
    (ego speed - the plan's target 500 m ahead), in s and s per m/s, clipped to 0-1.5 s."""

    label: str
    base_s: float
    per_rel_s: float = 0.0
    per_plan_ahead_s: float = 0.0


MARGINS: tuple[MarginProbe, ...] = (
    MarginProbe("margin 0 s", 0.0),
    MarginProbe("margin 0.75 s", 0.75),
    MarginProbe("margin 1.5 s", 1.5),
    MarginProbe("margin 0.75 s + 0.25 s/(m/s)", 0.75, per_rel_s=0.25),
    MarginProbe("margin 0.75 s + 0.125 s/(m/s)", 0.75, per_rel_s=0.125),
)
# Margins opened by the plan's foresight: the faster the AV drives than the plan 500 m ahead
# asks, the more room it keeps for the slowdown the plan sees coming.
PLAN_AHEAD_MARGINS: tuple[MarginProbe, ...] = (
    MarginProbe("0.1 s per m/s over the plan ahead", 0.0, per_plan_ahead_s=0.1),
    MarginProbe("0.25 s per m/s over the plan ahead", 0.0, per_plan_ahead_s=0.25),
    MarginProbe("0.4 s + 0.1 s per m/s over the plan ahead", 0.4, per_plan_ahead_s=0.1),
)
# (label, speed action component, gap action component) of the constant `acc` files
STOCK_ACC: tuple[tuple[str, float, float], ...] = (
    ("stock ACC at the ceiling, 1 bar", 1.0, -1.0),
    ("stock ACC at the ceiling, 3 bars", 1.0, 1.0),
)
# (window s, speed gain 1/s, gap gain 1/s^2, reference time gap s)
LEADER_AVERAGES: tuple[tuple[float, float, float, float], ...] = (
    (20.0, 0.2, 0.01, 1.5),
    (60.0, 0.2, 0.01, 1.5),
    (40.0, 0.2, 0.03, 2.0),
    (60.0, 0.2, 0.0, 1.5),
    (120.0, 0.1, 0.0, 1.5),
    (60.0, 0.2, 0.02, 3.0),
)


class SmoothingFollower(Controller):
    """Toward a reference speed taken from the leader (`reference_speed`, each subclass its
    own), plus `gap_gain` x (gap - the reference gap, `headway_s` x v within
    REFERENCE_GAP_MIN_M to REFERENCE_GAP_MAX_M), under a_safe like rl_accel. With no leader
    measured it closes up (toward CLOSING_MPS above its speed, or the plan's target if
    faster), as the `acc` rule closes up to a lost leader: otherwise it would save fuel by
    falling back."""

    def __init__(self, speed_gain: float, gap_gain: float, headway_s: float) -> None:
        super().__init__("accel")
        self.speed_gain = speed_gain
        self.gap_gain = gap_gain
        self.headway_s = headway_s
        self.lead_accel = LeadAccelEstimator(SAFETY.lead_accel_filter_s)

    def reset(self) -> None:
        """Forget the leader."""
        self.lead_accel.reset()

    def step(self, observation: Observation) -> AccelCommand:
        """The smoother's request, bounded as rl_accel's."""
        speed = observation.speed_mps
        if not observation.has_lead_state:
            self.reset()
            closing = max(observation.target_speed_mps, speed + CLOSING_MPS)
            request = self.speed_gain * (closing - speed)
            return AccelCommand(bounded_request(request, speed, None, None, 0.0))
        gap = float(observation.lead_distance_m)  # type: ignore[arg-type]
        rel = float(observation.lead_rel_speed_mps)  # type: ignore[arg-type]
        lead_accel = self.lead_accel.update(observation.time_s, speed + rel, gap)
        reference_gap = min(max(self.headway_s * speed, REFERENCE_GAP_MIN_M), REFERENCE_GAP_MAX_M)
        request = self.speed_gain * (
            self.reference_speed(observation, speed + rel) - speed
        ) + self.gap_gain * (gap - reference_gap)
        return AccelCommand(bounded_request(request, speed, gap, rel, lead_accel))

    @abstractmethod
    def reference_speed(self, observation: Observation, lead_speed_mps: float) -> float:
        """The speed to drive, given the leader's speed measured now."""


class LeaderAverageFollower(SmoothingFollower):
    """A smoother driving the leader's mean speed over the last `window_s` (one sample per
    simulator step, since the leader was last lost)."""

    name = "leader_average"

    def __init__(
        self, window_s: float, speed_gain: float, gap_gain: float, headway_s: float
    ) -> None:
        super().__init__(speed_gain, gap_gain, headway_s)
        self.lead_speeds: deque[float] = deque(maxlen=int(round(window_s / STEP_S)))

    def reset(self) -> None:
        """Forget the leader and its speeds."""
        super().reset()
        self.lead_speeds.clear()

    def reference_speed(self, observation: Observation, lead_speed_mps: float) -> float:
        """The leader's mean over the last `window_s` (this sample included)."""
        self.lead_speeds.append(lead_speed_mps)
        return float(np.mean(self.lead_speeds))


class ForesightFollower(SmoothingFollower):
    """A smoother that knows its leader's whole drive (`lead_speed_mps`, one sample per
    simulator step from time 0): the mean it drives spans `window_s`, of which `ahead_share`
    lies in the leader's future (0: the causal trailing mean, 0.5: centred on now, 1: the next
    `window_s`), cut at the drive's ends. An oracle for diagnosis only: it is right only for
    the AV directly behind the replayed leader, with no cut-ins."""

    name = "foresight"

    def __init__(
        self,
        lead_speed_mps: FloatArray,
        ahead_share: float,
        window_s: float,
        speed_gain: float,
        gap_gain: float,
        headway_s: float,
    ) -> None:
        super().__init__(speed_gain, gap_gain, headway_s)
        if not 0.0 <= ahead_share <= 1.0:
            raise ValueError(f"ahead_share is a share of the window, got {ahead_share}")
        # running sums, so each mean is two look-ups
        self.cumulative = np.concatenate([[0.0], np.cumsum(lead_speed_mps)])
        window = int(round(window_s / STEP_S))
        self.ahead_steps = int(round(ahead_share * window))
        self.behind_steps = window - self.ahead_steps

    def reference_speed(self, observation: Observation, lead_speed_mps: float) -> float:
        """The leader's mean from `behind_steps` before this step to `ahead_steps` after it."""
        step = int(round(observation.time_s / STEP_S))
        last = len(self.cumulative) - 1
        first = min(max(step - self.behind_steps + 1, 0), last - 1)
        end = max(min(step + self.ahead_steps + 1, last), first + 1)
        return float((self.cumulative[end] - self.cumulative[first]) / (end - first))


class ForecastFollower(LeaderAverageFollower):
    """A smoother driving `forecast`'s mean of its leader's speed over the window ahead, from
    the leader's speeds its radar measured since it last saw none (the trailing window's
    history, `forecast`'s reach long) and, for a forecast with the plan, the plan's targets at
    the leader's place (its gap and a car's length ahead) and the forecast's offsets beyond."""

    name = "forecast"

    def __init__(
        self, forecast: LeaderForecast, speed_gain: float, gap_gain: float, headway_s: float
    ) -> None:
        history_s = (int(forecast.lags[-1]) + 1) * STEP_S
        super().__init__(history_s, speed_gain, gap_gain, headway_s)
        self.forecast = forecast

    def reference_speed(self, observation: Observation, lead_speed_mps: float) -> float:
        """The forecast mean ahead from the history, this sample included (and the plan)."""
        self.lead_speeds.append(lead_speed_mps)
        targets: list[float] = []
        if self.forecast.plan_offsets_m:
            plan, position = observation.target, observation.position_m
            if plan is None or position is None or observation.lead_distance_m is None:
                raise ValueError(
                    "a forecast with the plan needs the plan, the car's position and its gap"
                )
            leader_m = position + observation.lead_distance_m + VEHICLE_LENGTH_M
            targets = [plan.at(leader_m + offset) for offset in self.forecast.plan_offsets_m]
        history = np.fromiter(self.lead_speeds, dtype=np.float64)
        return self.forecast.mean_ahead(history, targets)


# (share of the window ahead of now, window s); foresight of share x window. The first is the
# causal trailing mean; all drive with the gains of the best one of LEADER_AVERAGES (k 0.2 /s,
# pulled by 0.01 /s^2 toward 1.5 s of gap).
FORESIGHTS: tuple[tuple[float, float], ...] = (
    (0.0, 60.0),
    (0.5, 20.0),
    (1.0, 20.0),
    (0.5, 60.0),
    (1.0, 60.0),
    (0.5, 120.0),
    (1.0, 120.0),
)
FORESIGHT_GAINS = (0.2, 0.01, 1.5)


def margin_policies(folder: Path, probes: Sequence[MarginProbe]) -> list[ControllerUnderTest]:
    """One one-layer `request_time_margin` policy file per probe, in `folder`."""
    entries = []
    half = TIME_MARGIN_MAX_S / 2.0  # h = half x (1 + a1)
    for index, probe in enumerate(probes):
        weights = np.zeros((ACCEL_FEATURES, 2))
        weights[REL_SPEED_FEATURE, 1] = probe.per_rel_s / half * REL_SPEED_SCALE_MPS
        weights[SPEED_FEATURE, 1] = probe.per_plan_ahead_s / half * SPEED_SCALE_MPS
        weights[PLAN_AHEAD_FEATURE, 1] = -probe.per_plan_ahead_s / half * SPEED_SCALE_MPS
        biases = np.array([CONSTANT_REQUEST_MPS2 / ACCEL_ACTION_MAX_MPS2, probe.base_s / half - 1])
        path = folder / f"margin_{index}.npz"
        save_policy(path, "accel", [weights], [biases], "request_time_margin")
        entries.append(ControllerUnderTest.policy_file(probe.label, "accel", path))
    return entries


def stock_acc_policies(folder: Path) -> list[ControllerUnderTest]:
    """One one-layer constant `acc` policy file per entry of STOCK_ACC, in `folder`."""
    entries = []
    for index, (label, speed_action, gap_action) in enumerate(STOCK_ACC):
        path = folder / f"stock_acc_{index}.npz"
        save_policy(
            path, "acc", [np.zeros((ACC_FEATURES, 2))], [np.array([speed_action, gap_action])]
        )
        entries.append(ControllerUnderTest.policy_file(label, "acc", path))
    return entries


def leader_averages() -> list[ControllerUnderTest]:
    """One `LeaderAverageFollower` per entry of LEADER_AVERAGES."""
    entries = []
    for window_s, speed_gain, gap_gain, headway_s in LEADER_AVERAGES:
        label = f"mean over {window_s:g} s, k {speed_gain:g}, gap {gap_gain:g} at {headway_s:g} s"

        def build(
            window_s: float = window_s,
            speed_gain: float = speed_gain,
            gap_gain: float = gap_gain,
            headway_s: float = headway_s,
        ) -> Controller:
            return LeaderAverageFollower(window_s, speed_gain, gap_gain, headway_s)

        entries.append(ControllerUnderTest(label, "accel", build))
    return entries


def foresights(drive: Drive) -> list[ControllerUnderTest]:
    """One `ForesightFollower` per entry of FORESIGHTS, told `drive`'s leader."""
    speed_gain, gap_gain, headway_s = FORESIGHT_GAINS
    entries = []
    for ahead_share, window_s in FORESIGHTS:
        label = f"leader's mean over {window_s:g} s, {100 * ahead_share:.0f} % of it ahead"

        def build(ahead_share: float = ahead_share, window_s: float = window_s) -> Controller:
            return ForesightFollower(
                drive.speed_mps, ahead_share, window_s, speed_gain, gap_gain, headway_s
            )

        entries.append(ControllerUnderTest(label, "accel", build))
    return entries


def forecasts(fitted_on: Sequence[Drive]) -> list[ControllerUnderTest]:
    """Two `ForecastFollower`s, the forecasts (the leader's history; it and the plan) fitted
    on `fitted_on`, with the foresight followers' gains."""
    lags = lag_steps()
    # the plans the probes' runs hold (the RL training setting), not the fleet's
    features, change = drive_rows(
        fitted_on, lags, with_plan=True, planner_params=DEFAULT_PLANNER_PARAMS
    )
    history_only = fit_forecast(features[:, : len(lags) + 1], change, lags)
    with_plan = fit_forecast(features, change, lags, plan_offsets_m=PLAN_OFFSETS_M)
    speed_gain, gap_gain, headway_s = FORESIGHT_GAINS
    entries = []
    for label, forecast in (
        (f"forecast of the next {FORECAST_S:g} s, history", history_only),
        (f"forecast of the next {FORECAST_S:g} s, history and plan", with_plan),
    ):

        def build(forecast: LeaderForecast = forecast) -> Controller:
            return ForecastFollower(forecast, speed_gain, gap_gain, headway_s)

        entries.append(ControllerUnderTest(label, "accel", build))
    return entries


def main(argv: Sequence[str] | None = None) -> None:
    """Score one family on fold 0's training dates; one line per follower and group."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "family",
        choices=("margin", "plan-ahead", "leader-average", "stock-acc", "foresight", "forecast"),
    )
    parser.add_argument(
        "--files",
        type=Path,
        default=None,
        help="keep the family's policy files in this folder (for `sim evaluate`)",
    )
    args = parser.parse_args(argv)
    train = date_folds(load_drives(shared_data_dir() / "trajectories"), 2)[0].train
    say = print  # noqa: T201 (a command-line report)
    with tempfile.TemporaryDirectory() as scratch:
        folder = args.files or Path(scratch)
        folder.mkdir(parents=True, exist_ok=True)
        # (drives, the followers run on them): foresight followers know one drive's leader each
        batches: list[tuple[Sequence[Drive], list[ControllerUnderTest]]]
        if args.family == "foresight":
            batches = [([drive], foresights(drive)) for drive in train]
        elif args.family == "forecast":
            # each half of the training dates is run by the forecast fitted on the other
            batches = [(half.held_out, forecasts(half.train)) for half in date_folds(train, 2)]
        elif args.family == "margin":
            batches = [(train, margin_policies(folder, MARGINS))]
        elif args.family == "plan-ahead":
            batches = [(train, margin_policies(folder, PLAN_AHEAD_MARGINS))]
        elif args.family == "stock-acc":
            batches = [(train, stock_acc_policies(folder))]
        else:
            batches = [(train, leader_averages())]
        scores = [
            score
            for drives, entries in batches
            for score in score_drives(
                drives, entries, planner="kernel_smooth", planner_params=DEFAULT_PLANNER_PARAMS
            )
        ]
    for row in summarise(scores):
        say(
            f"{row['controller']:>45} {row['group']:>11}: fuel {row['fuel_saving_pct']:+.2f} %,"
            f" throughput {row['throughput_change_pct']:+.2f} %"
            f" (worst {row['worst_throughput_change_pct']:+.2f}), network speed"
            f" {row['network_speed_change_pct']:+.2f} %, collisions {row['collisions']},"
            f" within >= {row['min_gap_within_share']:.3f}"
        )
    for label in dict.fromkeys(score.controller for score in scores):
        within = [score.gap_within_share for score in scores if score.controller == label]
        say(f"{label:>45}: within the envelope {np.mean(within):.3f} of the time (mean)")


if __name__ == "__main__":
    main()
