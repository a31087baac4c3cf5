"""Choosing the reward's weights c1..c4 by cross-validation nested inside an outer fold's dates.

The weights of `RewardWeights` shape what PPO learns, so they are a parameter like any gain: one
chosen and scored on the same drives is not a result. `select_reward` is run on an outer fold's
training dates only. It splits them again by date (`sim.folds.date_folds`, two inner folds),
trains every candidate on one inner fold's dates and scores it on the other's, both ways, and
pools the two inner held-out halves. The outer fold's held-out dates are never read, so the
policy the outer fold then trains with the chosen weights is scored on dates the choice did not
see. The inner scores have the cut-ins the training had (`EnvConfig.cut_ins`).

The rule (`admissibility`, `choose`) is the issue's: a candidate is admissible when, in every
group of drives, mean throughput and network speed stay within `MAX_LOSS_PCT`, on the freeflow
drives within `MAX_FREEFLOW_LOSS_PCT`, no AV touches its leader nor needs its driver to stop
(a takeover, `DriveScore.takeovers`), and the AVs keep the gap
envelope at least `MIN_WITHIN_SHARE` of the time. Among the admissible, the highest mean fuel
saving on the shockwave drives wins; a tie, or no admissible candidate, goes to the first
candidate (the weights used until the data shows better ones).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from sim.drives import Drive
from sim.folds import date_folds, drive_date
from sim.recorded import RecordedDrive
from sim.rl.env import EnvConfig, RewardWeights
from sim.rl.scores import (
    GROUPS,
    ControllerUnderTest,
    DriveScore,
    group_mean,
    score_drives,
    scoring_progress,
)
from sim.rl.train import PpoSettings, export_policy, stage_progress, train_policy

INNER_FOLDS = 2
MAX_LOSS_PCT = -2.0
MAX_FREEFLOW_LOSS_PCT = -1.0
MIN_WITHIN_SHARE = 0.99
CHOSEN_BY = "shockwave"  # the group whose mean fuel saving ranks the admissible candidates


class RewardCandidateError(ValueError):
    """A reward candidate that names no weight of `RewardWeights` or gives an invalid one."""


def parse_reward_candidates(text: str) -> list[RewardWeights]:
    """`reward_candidates` of a JSON list of weight changes (the command line's form)."""
    try:
        changes = json.loads(text)
    except json.JSONDecodeError as error:
        raise RewardCandidateError(f"not JSON ({error.msg} at character {error.pos})") from None
    if not isinstance(changes, list) or not changes:
        raise RewardCandidateError(
            'a non-empty JSON list of weight changes is expected, e.g. [{"fuel": 0.6}]'
        )
    return reward_candidates(changes)


def reward_candidates(changes: Sequence[Any]) -> list[RewardWeights]:
    """The defaults first, then each of `changes` applied to the defaults (one dict each)."""
    known = set(RewardWeights.__dataclass_fields__)
    candidates = [RewardWeights()]
    for index, change in enumerate(changes):
        if not isinstance(change, Mapping) or not change:
            raise RewardCandidateError(
                f'reward candidate {index} must be an object of weights, e.g. {{"fuel": 0.6}}'
            )
        unknown = sorted(set(change) - known)
        if unknown:
            raise RewardCandidateError(
                f"reward candidate {index} names {', '.join(unknown)}: the weights are "
                f"{', '.join(sorted(known))}"
            )
        values: dict[str, float] = {}
        for name, value in change.items():
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise RewardCandidateError(
                    f"reward candidate {index}: {name} must be a number, got {value!r}"
                )
            if not np.isfinite(value) or value < 0:
                raise RewardCandidateError(
                    f"reward candidate {index}: {name} must be finite and >= 0, got {value}"
                )
            values[name] = float(value)
        weights = replace(RewardWeights(), **values)
        if weights in candidates:
            raise RewardCandidateError(f"reward candidate {index} repeats an earlier one")
        candidates.append(weights)
    return candidates


def admissibility(scores: Sequence[DriveScore]) -> list[str]:
    """Why one candidate's pooled inner held-out scores break the issue's bounds (none: [])."""
    broken = []
    for group, member in GROUPS.items():
        chosen = [score for score in scores if member(score)]
        if not chosen:
            continue
        floor = MAX_FREEFLOW_LOSS_PCT if group == "freeflow" else MAX_LOSS_PCT
        for column, figure in (
            ("throughput_change_pct", "throughput"),
            ("network_speed_change_pct", "network speed"),
        ):
            change = group_mean(chosen, column)
            if not math.isfinite(change):
                # a drive the candidate left without a figure (it stalled the platoon)
                broken.append(f"{group} {figure} undefined")
            elif change < floor:
                broken.append(f"{group} {figure} {change:+.2f} % < {floor:+.0f} %")
    collisions = sum(score.collisions for score in scores)
    if collisions:
        broken.append(f"{collisions} collision(s)")
    # Since the scores run the agent's hand-back (2026-12-05), a stop the AV could not make is
    # its driver's, not a collision: counted as one here, or a candidate that needed its
    # driver would pass where, without the hand-back, it was refused for the collision.
    takeovers = sum(score.takeovers or 0 for score in scores)
    if takeovers:
        broken.append(f"{takeovers} takeover(s)")
    within = float(np.mean([score.gap_within_share for score in scores]))
    if within < MIN_WITHIN_SHARE:
        broken.append(f"within the envelope {100 * within:.1f} % < {100 * MIN_WITHIN_SHARE:.0f} %")
    return broken


def ranking_fuel_saving_pct(scores: Sequence[DriveScore]) -> float:
    """Mean fuel saving over the drives of the ranking group whose all-human platoon measures
    it (`group_mean`; NaN if it has none)."""
    member = GROUPS[CHOSEN_BY]
    return group_mean([score for score in scores if member(score)], "fuel_saving_pct")


def choose(candidate_scores: Sequence[Sequence[DriveScore]]) -> int:
    """The index of the chosen candidate: the admissible one saving the most fuel on the
    ranking group, else the first."""
    best, best_saving = 0, -np.inf
    for index, scores in enumerate(candidate_scores):
        saving = ranking_fuel_saving_pct(scores)
        if admissibility(scores) or not np.isfinite(saving):
            continue
        if saving > best_saving:
            best, best_saving = index, saving
    return best


@dataclass(frozen=True)
class RewardSelection:
    """What `select_reward` found: the chosen weights and every candidate's pooled record."""

    chosen: RewardWeights
    chosen_index: int
    inner_folds: list[dict[str, Any]]
    candidates: list[dict[str, Any]]

    def as_dict(self) -> dict[str, Any]:
        """The manifest's record of the selection."""
        return {
            "rule": (
                "admissible: every group's mean throughput and network speed"
                f" >= {MAX_LOSS_PCT:+g} % (freeflow >= {MAX_FREEFLOW_LOSS_PCT:+g} %),"
                " 0 collisions, within the envelope"
                f" >= {100 * MIN_WITHIN_SHARE:g} %; then the highest mean fuel saving on the"
                f" {CHOSEN_BY} drives; none admissible or a tie: the first candidate"
            ),
            "inner_folds": self.inner_folds,
            "candidates": self.candidates,
            "chosen_index": self.chosen_index,
            "chosen": asdict(self.chosen),
        }


def select_reward(
    drives: Sequence[Drive],
    config: EnvConfig,
    candidates: Sequence[RewardWeights],
    settings: PpoSettings,
    *,
    timesteps: int,
    seed: int,
    out_dir: Path,
    stage: str,
    progress: Callable[[str, int, int], None] | None = None,
    recorded: Sequence[RecordedDrive] = (),
) -> RewardSelection:
    """Train and score every candidate across `drives`' inner date folds; choose by the rule.

    Each inner training also drives the `recorded` drives of its own dates on their real INRIX.
    The inner policies are written under `out_dir` (one file per candidate and inner fold).
    """
    if not candidates:
        raise ValueError("the selection needs at least one reward candidate")
    dates = sorted({drive_date(drive) for drive in drives})
    if len(dates) < INNER_FOLDS:
        raise ValueError(
            f"the reward selection of {stage} splits its training dates in {INNER_FOLDS} by date,"
            f" but it trains on {len(dates)} ({', '.join(dates)}): it needs drives of more dates"
        )
    inner = date_folds(drives, INNER_FOLDS)
    name = f"rl_{config.actuation}"
    pooled: list[list[DriveScore]] = []
    for index, weights in enumerate(candidates):
        scores: list[DriveScore] = []
        for fold in inner:
            label = f"{stage} reward {index} inner {fold.index}"
            report = stage_progress(progress, label, timesteps)
            model = train_policy(
                fold.train,
                replace(config, reward=weights),
                settings,
                timesteps,
                seed,
                report,
                recorded,
            )
            path = out_dir / f"{name}_reward{index}_inner{fold.index}.npz"
            export_policy(model, path, config)
            scores.extend(
                score_drives(
                    fold.held_out,
                    [ControllerUnderTest.policy_file(name, config.actuation, path)],
                    planner=config.planner,
                    planner_params=config.planner_params,
                    bounds=config.gap_bounds,
                    cut_ins=config.cut_ins,
                    progress=scoring_progress(progress, f"{label} held-out", len(fold.held_out)),
                )
            )
        pooled.append(scores)
    chosen = choose(pooled)
    records = []
    for weights, scores in zip(candidates, pooled, strict=True):
        broken = admissibility(scores)
        records.append(
            {
                "weights": asdict(weights),
                "admissible": not broken,
                "broken": broken,
                f"{CHOSEN_BY}_fuel_saving_pct": ranking_fuel_saving_pct(scores),
                "mean_within_share": float(np.mean([score.gap_within_share for score in scores])),
                "drives": [score.as_dict() for score in scores],
            }
        )
    folds = [
        {"fold": fold.index, "train_dates": fold.train_dates, "held_out_dates": fold.held_out_dates}
        for fold in inner
    ]
    return RewardSelection(candidates[chosen], chosen, folds, records)
