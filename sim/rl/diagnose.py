"""Where an RL policy leaves the gap envelope and what sets its command, on training dates only.

`python -m sim.rl.diagnose POLICY.npz [--actuation acc|accel] [--fold 0]`: the policy (behind
the paper's clip on `acc`, under a_safe on `accel`) as the one AV of a 24-human platoon on every
drive of fold `--fold`'s training dates (`sim.folds`, two folds), `kernel_smooth` with the
training set-up's planner. Per drive: the share of time within the envelope and why not (gap
under its minimum, over its maximum, time gap under its minimum), the mean gap, the AV's and its
leader's mean speed, how often the leader was lost (beyond the radar's range) and the AV's
acceleration RMS beside the human driving in its place. On `accel`, also how often the safety
bound a_safe, not the network, set the command, and the network's requests (`SafetyBoundShare`),
with the time margins it added to a_safe's gap when its action has them.
A shipped policy is fold 0's, so its held-out dates (fold 0's other dates) are not looked at.
They are also fold 1's training dates, so after a change this diagnosis shaped, fold 0's
held-out dates are the only ones it has not read: report them apart from the all-drive figures.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.av import RADAR_RANGE_M
from sim.drives import load_drives, shared_data_dir
from sim.folds import date_folds
from sim.gaps import GapBounds
from sim.platoon import PlatoonRun, platoon_roles, simulate_platoon
from sim.rl.env import DEFAULT_PLANNER_PARAMS
from sim.rl.scores import ControllerUnderTest, simulate_one_av
from vehicle_agent.controllers import AccelCommand, Action, Controller, Observation

HUMANS = 24  # behind the AV: 4 % penetration, as in training and the held-out scores
# A command this far below the request was lowered by the bound, not rounded.
BOUND_TOLERANCE_MPS2 = 1e-9


@dataclass(frozen=True)
class GapDiagnosis:
    """The first follower's (the AV's) time against the envelope, as shares of the run."""

    under_min_gap: float
    over_max_gap: float
    under_time_gap: float  # and not already under the minimum gap
    leader_lost: float  # gap beyond the radar's range
    leader_lost_episodes: int
    mean_gap_m: float
    accel_rms_mps2: float

    @property
    def within(self) -> float:
        """Share of time inside the envelope."""
        return 1.0 - self.under_min_gap - self.over_max_gap - self.under_time_gap


def diagnose_first_follower(run: PlatoonRun, bounds: GapBounds) -> GapDiagnosis:
    """Why vehicle 1 (right behind the leader) was outside `bounds`, and how it drove."""
    gap = run.gap_m[:, 0]
    speed = run.speed_mps[:, 1]
    below = gap < bounds.min_gap_m
    lost = gap > RADAR_RANGE_M
    accel = np.diff(speed) / run.dt_s
    return GapDiagnosis(
        under_min_gap=float(below.mean()),
        over_max_gap=float((gap > bounds.max_gap_m).mean()),
        under_time_gap=float((bounds.under_time_gap(gap, speed) & ~below).mean()),
        leader_lost=float(lost.mean()),
        leader_lost_episodes=int(np.count_nonzero(lost[1:] & ~lost[:-1])),
        mean_gap_m=float(gap.mean()),
        accel_rms_mps2=float(np.sqrt(np.mean(accel**2))),
    )


@dataclass(frozen=True)
class SafetyBoundShare:
    """An `accel` policy's commands against its requests: how often a_safe decided."""

    bound_share: float  # the command was below the network's request
    request_mean_mps2: float
    request_p5_mps2: float
    request_p95_mps2: float
    margin_mean_s: float  # the time margin added to a_safe's gap (0 without the margin action)
    margin_p5_s: float
    margin_p95_s: float


def safety_bound_share(commands: Sequence[AccelCommand]) -> SafetyBoundShare:
    """Share of commands a_safe (with any margin) lowered below the request; the spread of the
    requests and of the margins."""
    request = np.array([command.requested_accel_mps2 for command in commands])
    given = np.array([command.accel_mps2 for command in commands])
    margin = np.array([command.time_margin_s for command in commands])
    if not np.all(np.isfinite(request)):
        raise ValueError("every command must carry the policy's request")
    p5, p95 = np.percentile(request, [5.0, 95.0])
    margin_p5, margin_p95 = np.percentile(margin, [5.0, 95.0])
    return SafetyBoundShare(
        bound_share=float(np.mean(given < request - BOUND_TOLERANCE_MPS2)),
        request_mean_mps2=float(request.mean()),
        request_p5_mps2=float(p5),
        request_p95_mps2=float(p95),
        margin_mean_s=float(margin.mean()),
        margin_p5_s=float(margin_p5),
        margin_p95_s=float(margin_p95),
    )


class RecordingController(Controller):
    """Runs another controller unchanged and keeps every action it gave."""

    name = "recording"

    def __init__(self, inner: Controller) -> None:
        super().__init__(inner.actuation)
        self.inner = inner
        self.actions: list[Action] = []

    def step(self, observation: Observation) -> Action:
        """The inner controller's action, recorded."""
        action = self.inner.step(observation)
        self.actions.append(action)
        return action

    def reset(self) -> None:
        """The inner controller forgets its past."""
        self.inner.reset()


def main(argv: Sequence[str] | None = None) -> None:
    """Print one line per training-date drive, then the shares over all their time."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy", type=Path)
    parser.add_argument("--actuation", choices=("acc", "accel"), default="acc")
    parser.add_argument("--fold", type=int, default=0)
    args = parser.parse_args(argv)
    drives = load_drives(shared_data_dir() / "trajectories")
    fold = date_folds(drives, 2)[args.fold]
    policy = ControllerUnderTest.policy_file(f"rl_{args.actuation}", args.actuation, args.policy)
    recorder: list[RecordingController] = []

    def recording() -> Controller:
        recorder.append(RecordingController(policy.build()))
        return recorder[-1]

    entry = ControllerUnderTest(policy.label, policy.actuation, recording)
    commands: list[AccelCommand] = []
    bounds = GapBounds()
    say = print  # noqa: T201 (a command-line report)
    say(f"fold {args.fold}'s training dates: {', '.join(fold.train_dates)}")
    rows = 0
    outside = np.zeros(3)  # under the minimum gap, over the maximum, under the time gap (rows)
    for drive in fold.train:
        run = simulate_one_av(
            drive,
            entry,
            planner="kernel_smooth",
            planner_params=DEFAULT_PLANNER_PARAMS,
            humans=HUMANS,
        )
        av = diagnose_first_follower(run, bounds)
        steps = run.position_m.shape[0]
        rows += steps
        outside += steps * np.array([av.under_min_gap, av.over_max_gap, av.under_time_gap])
        human = diagnose_first_follower(
            simulate_platoon(drive, platoon_roles(HUMANS + 1, 0)), bounds
        )
        accel = [action for action in recorder[-1].actions if isinstance(action, AccelCommand)]
        commands.extend(accel)
        say(
            f"{drive.name[:19]} {drive.kind:9s} within {av.within:.2f}"
            f" | <{bounds.min_gap_m:g} m {av.under_min_gap:.2f}"
            f" >{bounds.max_gap_m:g} m {av.over_max_gap:.2f} time gap {av.under_time_gap:.2f}"
            f" | mean gap {av.mean_gap_m:.0f} m, AV {run.speed_mps[:, 1].mean():.1f} m/s,"
            f" leader {run.speed_mps[:, 0].mean():.1f} m/s"
            f" | leader lost {av.leader_lost:.2f} in {av.leader_lost_episodes} episodes"
            f" | accel RMS {av.accel_rms_mps2:.2f} (human in its place {human.accel_rms_mps2:.2f})"
            + _bound_text(accel)
        )
    under, over, short = outside / rows
    say(
        f"every drive's time: outside {under + over + short:.3f} = under {under:.3f}"
        f" + over {over:.3f} + time gap {short:.4f}" + _bound_text(commands)
    )


def _bound_text(commands: Sequence[AccelCommand]) -> str:
    """` | a_safe set ...` for acceleration commands; nothing without any (an `acc` policy)."""
    if not commands:
        return ""
    seen = safety_bound_share(commands)
    margins = (
        f"; time margin mean {seen.margin_mean_s:.2f} s (5-95 %: {seen.margin_p5_s:.2f}"
        f" to {seen.margin_p95_s:.2f})"
        if seen.margin_p95_s > 0.0
        else ""
    )
    return (
        f" | a_safe set the command {seen.bound_share:.3f} of the time; requests mean"
        f" {seen.request_mean_mps2:+.2f} m/s^2 (5-95 %: {seen.request_p5_mps2:+.2f}"
        f" to {seen.request_p95_mps2:+.2f})" + margins
    )


if __name__ == "__main__":
    main()
