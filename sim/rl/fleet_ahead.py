"""What a fleet car 24 vehicles ahead, relayed through the server, tells a car of its leader.

    .venv/bin/python -m sim.rl.fleet_ahead skill      # forecast skill, held out by date
    .venv/bin/python -m sim.rl.fleet_ahead closed-loop  # the smoother driving each forecast

A diagnostic registered before it was written (docs/simulation/fleet-ahead-relay-
preregistered.md); nothing is chosen on it and nothing shipped comes from it. The foresight
probe (`sim.rl.hand_probes foresight`) found that a forecast of the leader's next 20 s is what
lies between rl_accel and the optimal bound, and `sim.leader_forecast` that neither the radar's
history nor the minute-old plan holds it. The server receives every fleet car's ping each
second; this asks what those of a fleet car further ahead would add, passed on to the car
behind within seconds.

The platoon: the replayed leader, 49 followers, AVs at followers 0 and 24 (1 in 25, the paper's
penetration). The front AV runs the shipped rl_accel. Each of its pings (1 Hz, as the agent
sends them) reaches the rear AV `latency_s` after it was sent (`FleetRelay`). The forecast is a
ridge, as `sim.leader_forecast`'s, of the change from the rear AV's leader's speed now to its
mean over the next 20 s, on that leader's radar history and, for `with_fleet`, on the relayed
speeds of the front AV, each less the leader's speed now.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from sim.av import PING_EVERY_STEPS, AgentPolicy, PlanSource
from sim.drives import STEP_S, Drive, load_drives, shared_data_dir
from sim.energy import RAV4_2019
from sim.folds import date_folds
from sim.gaps import GapBounds
from sim.kpi import platoon_kpis
from sim.leader_forecast import (
    DRIVE_GROUPS,
    FORECAST_S,
    SAMPLE_EVERY_S,
    fit_forecast,
    forecast_rows,
    forecast_steps,
    history_features,
    lag_steps,
)
from sim.plans import SimulatedPlanner
from sim.platoon import PlatoonRun, platoon_roles, simulate_platoon
from sim.rl.env import DEFAULT_PLANNER_PARAMS
from sim.rl.hand_probes import FORESIGHT_GAINS, ForesightFollower, LeaderAverageFollower
from sim.rl.scores import ControllerUnderTest, DriveScore, score_run, summarise
from vehicle_agent.controllers import Controller, Observation, TargetProfile

FloatArray = NDArray[np.float64]

# 49 followers, 2 of them AVs: followers 0 and 24 (`platoon_roles`), 1 in 25.
FOLLOWERS = 49
AVS = 2
REAR_AV_COLUMN = 25  # follower 24 (column 0 is the leader)
# The relay's delay: a once-a-second poll of the server plus the transfer (registered), and
# the bracket.
LATENCY_S = 2.0
BRACKET_LATENCY_S = 5.0
# The relayed speeds the forecast reads: the newest ping received and one every 2 s for the
# minute before it.
FLEET_HISTORY_S = 60.0
FLEET_LAG_EVERY_S = 2.0
PLANNER = "kernel_smooth"


@dataclass
class FleetRelay:
    """The front AV's pings as the server would pass them on: each ping (time sent, speed) is
    received `latency_s` after it was sent."""

    latency_s: float
    sent_s: list[float] = field(default_factory=list)
    speed_mps: list[float] = field(default_factory=list)

    def record(self, time_s: float, speed_mps: float) -> None:
        """A ping the front AV sent."""
        self.sent_s.append(time_s)
        self.speed_mps.append(speed_mps)

    def received(self, now_s: float) -> FloatArray:
        """The speeds of every ping received by `now_s`, oldest first (a small tolerance, so
        a ping sent exactly `latency_s` ago counts whatever the float rounding)."""
        count = int(np.searchsorted(self.sent_s, now_s - self.latency_s + 1e-6, side="right"))
        return np.asarray(self.speed_mps[:count], dtype=np.float64)


class RelayingPlanSource:
    """The front AV's plan source: the planner's, and every ping also goes to the relay."""

    def __init__(self, plan: PlanSource, relay: FleetRelay) -> None:
        self.plan = plan
        self.relay = relay

    def profile(self, time_s: float) -> TargetProfile | None:
        """The planner's plan."""
        return self.plan.profile(time_s)

    def record_ping(
        self, time_s: float, x_m: float, speed_mps: float, *, engaged: bool, lead_present: bool
    ) -> None:
        """To the planner, as every ping, and to the relay."""
        self.plan.record_ping(time_s, x_m, speed_mps, engaged=engaged, lead_present=lead_present)
        self.relay.record(time_s, speed_mps)


def fleet_lags() -> NDArray[np.int64]:
    """Pings back from the newest received, 0 first: one every FLEET_LAG_EVERY_S over
    FLEET_HISTORY_S (the agent pings once a second)."""
    return np.arange(0, int(FLEET_HISTORY_S) + 1, int(FLEET_LAG_EVERY_S))


def fleet_features(received_mps: FloatArray, leader_now_mps: float) -> FloatArray:
    """The relayed speeds at `fleet_lags` back from the newest (padded with the oldest when
    fewer were received; the leader's speed when none was), less the leader's speed now."""
    lags = fleet_lags()
    needed = int(lags[-1]) + 1
    pings = np.asarray(received_mps, dtype=np.float64)
    if len(pings) == 0:
        pings = np.array([leader_now_mps])
    if len(pings) < needed:
        pings = np.concatenate((np.full(needed - len(pings), pings[0]), pings))
    newest_first = pings[::-1]
    features: FloatArray = newest_first[lags] - leader_now_mps
    return features


@dataclass(frozen=True)
class FleetForecast:
    """Ridge weights on the leader's `history_features` and, `with_fleet`, the relayed
    speeds' `fleet_features`: the change to the leader's mean over the next FORECAST_S."""

    weights: FloatArray
    lags: NDArray[np.int64]
    with_fleet: bool

    def mean_ahead(self, past_speeds: FloatArray, received_mps: FloatArray) -> float:
        """The forecast mean ahead from the leader's history (oldest first, now last; a
        shorter one padded with its oldest speed, as `LeaderForecast` pads) and the pings
        received."""
        needed = int(self.lags[-1]) + 1
        history = np.asarray(past_speeds, dtype=np.float64)
        if len(history) < needed:
            history = np.concatenate((np.full(needed - len(history), history[0]), history))
        now = float(history[-1])
        features = history_features(history[None, -needed:], self.lags)[0]
        if self.with_fleet:
            features = np.concatenate((features, fleet_features(received_mps, now)))
        return now + float(features @ self.weights)


def fit_fleet_forecast(features: FloatArray, change: FloatArray, with_fleet: bool) -> FleetForecast:
    """`sim.leader_forecast`'s ridge, on these rows."""
    lags = lag_steps()
    return FleetForecast(fit_forecast(features, change, lags).weights, lags, with_fleet)


class FleetForecastFollower(LeaderAverageFollower):
    """The hand probes' smoother driving a `FleetForecast` of its leader's next FORECAST_S,
    from its radar's history of the leader and the pings the relay has passed on."""

    name = "fleet_forecast"

    def __init__(
        self,
        forecast: FleetForecast,
        relay: FleetRelay,
        speed_gain: float,
        gap_gain: float,
        headway_s: float,
    ) -> None:
        super().__init__((int(forecast.lags[-1]) + 1) * STEP_S, speed_gain, gap_gain, headway_s)
        self.forecast = forecast
        self.relay = relay

    def reference_speed(self, observation: Observation, lead_speed_mps: float) -> float:
        """The forecast mean ahead, this radar sample included."""
        self.lead_speeds.append(lead_speed_mps)
        history = np.fromiter(self.lead_speeds, dtype=np.float64)
        return self.forecast.mean_ahead(history, self.relay.received(observation.time_s))


@dataclass(frozen=True)
class RearAv:
    """A controller for the rear AV: a label, the relay's delay, and how to build the
    controller on the run's relay."""

    label: str
    latency_s: float
    build: Callable[[FleetRelay], Controller]


# The front AV in every run, and the rear AV of the reference runs the forecasts are fitted on.
SHIPPED = ControllerUnderTest.registered("rl_accel", "accel", {})
REFERENCE = RearAv("rl_accel (shipped)", LATENCY_S, lambda relay: SHIPPED.build())


def relayed_run(drive: Drive, rear: RearAv) -> PlatoonRun:
    """The drive with the shipped rl_accel at follower 0 relaying its pings, `rear` at
    follower 24, I-24 IDM humans between and behind, the planner pinged by both AVs."""
    schedule = SimulatedPlanner.for_drive(drive, PLANNER, DEFAULT_PLANNER_PARAMS)
    relay = FleetRelay(rear.latency_s)
    policies = [
        AgentPolicy(SHIPPED.build(), RelayingPlanSource(schedule, relay), senses_lead_state=True),
        AgentPolicy(rear.build(relay), schedule, senses_lead_state=True),
    ]
    return simulate_platoon(
        drive,
        platoon_roles(FOLLOWERS - AVS, AVS),
        policies,
        av_max_accel=lambda v: float(RAV4_2019.max_accel_mps2(v)),
    )


def relayed_pings(run: PlatoonRun, latency_s: float) -> FleetRelay:
    """The relay of a finished run, rebuilt from its front AV's speeds: the agent pings at its
    first step and every PING_EVERY_STEPS after."""
    relay = FleetRelay(latency_s)
    for step in range(0, len(run.speed_mps), PING_EVERY_STEPS):
        relay.record(step * run.dt_s, float(run.speed_mps[step, 1]))
    return relay


def run_rows(run: PlatoonRun, with_fleet: bool, latency_s: float) -> tuple[FloatArray, FloatArray]:
    """One forecast row per second of a run: the rear AV's leader's history, as
    `sim.leader_forecast` reads the replayed leader's, and `with_fleet` the relayed pings'
    features; and the change to come."""
    lags = lag_steps()
    leader = run.speed_mps[:, REAR_AV_COLUMN - 1]
    ahead = int(round(FORECAST_S / STEP_S))
    every = int(round(SAMPLE_EVERY_S / STEP_S))
    rows, change = forecast_rows(leader, lags, ahead, every)
    if not with_fleet:
        return rows, change
    relay = relayed_pings(run, latency_s)
    steps = forecast_steps(len(leader), lags, ahead, every)
    fleet = [fleet_features(relay.received(step * run.dt_s), float(leader[step])) for step in steps]
    return np.hstack([rows, np.vstack(fleet)]), change


@dataclass(frozen=True)
class Forecaster:
    """One forecast of the study: a label, whether it reads the relay, and the relay's delay."""

    label: str
    with_fleet: bool
    latency_s: float

    def rows(self, runs: Sequence[PlatoonRun]) -> tuple[FloatArray, FloatArray]:
        """`run_rows` of every run, stacked."""
        pairs = [run_rows(run, self.with_fleet, self.latency_s) for run in runs]
        return np.vstack([rows for rows, _ in pairs]), np.concatenate([c for _, c in pairs])

    def fitted(self, runs: Sequence[PlatoonRun]) -> FleetForecast:
        """This forecast fitted on every second of `runs`."""
        return fit_fleet_forecast(*self.rows(runs), self.with_fleet)


FORECASTERS = (
    Forecaster("the leader's history", False, LATENCY_S),
    Forecaster(f"it and the fleet car ahead, {LATENCY_S:g} s relay", True, LATENCY_S),
    Forecaster(
        f"it and the fleet car ahead, {BRACKET_LATENCY_S:g} s relay", True, BRACKET_LATENCY_S
    ),
)


def skill_lines(drives: Sequence[Drive]) -> list[str]:
    """Per date fold and group of its held-out drives: each forecast's RMSE and skill (the
    share of persistence's squared error it removes), fitted on the fold's training dates."""
    runs = {drive.name: relayed_run(drive, REFERENCE) for drive in drives}
    lines = []
    for fold in date_folds(drives, 2):
        fits = [f.fitted([runs[d.name] for d in fold.train]) for f in FORECASTERS]
        for group, member in DRIVE_GROUPS.items():
            chosen = [runs[d.name] for d in fold.held_out if member(d)]
            if not chosen:
                continue
            change = FORECASTERS[0].rows(chosen)[1]
            persistence = _rmse(change)
            parts = [f"{len(change)} forecasts, persistence {persistence:.2f} m/s"]
            for forecaster, forecast in zip(FORECASTERS, fits, strict=True):
                features, change = forecaster.rows(chosen)
                rmse = _rmse(change - features @ forecast.weights)
                skill = 1 - (rmse / persistence) ** 2
                parts.append(f"{forecaster.label} {rmse:.2f} m/s (skill {skill:+.2f})")
            lines.append(f"fold {fold.index} {group}: " + "; ".join(parts))
    return lines


def _rmse(error: FloatArray) -> float:
    return float(np.sqrt(np.mean(error**2)))


def closed_loop(train: Sequence[Drive]) -> tuple[list[DriveScore], list[str]]:
    """Fold 0's training dates, each half run by the forecasts fitted on the other half: in
    the rear rl_accel, the smoother on each forecast, and the smoother on its leader's next
    FORECAST_S as the reference run drove it (the oracle). Returns the scores and, per drive,
    how far the oracle run's leader moved from the reference run's (RMS)."""
    speed_gain, gap_gain, headway_s = FORESIGHT_GAINS
    reference = {drive.name: relayed_run(drive, REFERENCE) for drive in train}
    scores, moved = [], []
    for half in date_folds(train, 2):
        rears = []
        for forecaster in FORECASTERS:
            forecast = forecaster.fitted([reference[d.name] for d in half.train])

            def build(relay: FleetRelay, forecast: FleetForecast = forecast) -> Controller:
                return FleetForecastFollower(forecast, relay, speed_gain, gap_gain, headway_s)

            rears.append(RearAv(f"smoother on {forecaster.label}", forecaster.latency_s, build))
        for drive in half.held_out:
            base_run = simulate_platoon(drive, platoon_roles(FOLLOWERS, 0))
            base = platoon_kpis(base_run)
            leader = reference[drive.name].speed_mps[:, REAR_AV_COLUMN - 1]

            def oracle(relay: FleetRelay, leader: FloatArray = leader) -> Controller:
                return ForesightFollower(leader, 1.0, FORECAST_S, speed_gain, gap_gain, headway_s)

            oracle_rear = RearAv(f"smoother on the next {FORECAST_S:g} s (oracle)", 0.0, oracle)
            runs = [(REFERENCE, reference[drive.name])]
            runs += [(rear, relayed_run(drive, rear)) for rear in [*rears, oracle_rear]]
            oracle_leader = runs[-1][1].speed_mps[:, REAR_AV_COLUMN - 1]
            moved.append(f"{drive.name}: {_rmse(oracle_leader - leader):.3f} m/s")
            scores += [
                score_run(drive, rear.label, base_run, base, run, GapBounds()) for rear, run in runs
            ]
    return scores, moved


def main(argv: Sequence[str] | None = None) -> None:
    """`skill`: held-out forecast skill on all 32 drives; `closed-loop`: fold 0's training
    dates, one line per rear AV and group."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", choices=("skill", "closed-loop"))
    args = parser.parse_args(argv)
    drives = load_drives(shared_data_dir() / "trajectories")
    say = print  # noqa: T201 (a command-line report)
    if args.part == "skill":
        for line in skill_lines(drives):
            say(line)
        return
    scores, moved = closed_loop(date_folds(drives, 2)[0].train)
    say("the oracle's leader, against the reference run's: " + "; ".join(moved))
    for row in summarise(scores):
        say(
            f"{row['controller']:>55} {row['group']:>11}: fuel {row['fuel_saving_pct']:+.2f} %,"
            f" throughput {row['throughput_change_pct']:+.2f} %"
            f" (worst {row['worst_throughput_change_pct']:+.2f}), network speed"
            f" {row['network_speed_change_pct']:+.2f} % (worst"
            f" {row['worst_network_speed_change_pct']:+.2f}), collisions {row['collisions']},"
            f" within >= {row['min_gap_within_share']:.3f}, lost {row['distance_lost_m']:+.0f} m"
        )


if __name__ == "__main__":
    main()
