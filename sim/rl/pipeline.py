"""`smoothfleet sim train` end to end: folds by date, PPO per fold, held-out scores, the shipped
policy and its manifest.

Cross-validation keeps whole dates apart (`sim.folds`): fold k's policy trains on the other
folds' dates and is scored only on its own held-out dates, beside the reference controller of
the same actuation on the same drives, so every figure in the manifest is held out. The shipped
policy is then trained the same way on every date (or, with `final=False`, fold 0's policy is
shipped and its manifest says so). Nothing is tuned on the held-out drives: the hyperparameters
(`PpoSettings`) are fixed before any run, and the reward (`RewardWeights`) is either fixed too or,
given candidates, chosen inside each fold on its training dates alone (`sim.rl.reward_selection`),
so a fold's held-out scores are of weights chosen without them.
"""

from __future__ import annotations

import hashlib
import json
import math
import platform
import shutil
import subprocess
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import stable_baselines3
import torch

from sim.drives import Drive
from sim.folds import Fold, date_folds, drive_date
from sim.recorded import RecordedDrive
from sim.rl.env import EnvConfig, RewardWeights
from sim.rl.restarts import RestartScores, choose_restart
from sim.rl.reward_selection import select_reward
from sim.rl.scores import (
    ControllerUnderTest,
    DriveScore,
    score_drives,
    scoring_progress,
    summarise,
)
from sim.rl.train import (
    PpoSettings,
    export_policy,
    recorded_on_dates_of,
    stage_progress,
    train_policy,
)

# What each RL controller is scored beside: the hand-designed controller of the same actuation
# with the gain docs/simulation.md's evaluation found best.
REFERENCES: dict[str, ControllerUnderTest] = {
    "acc": ControllerUnderTest.registered("microaccel_acc", "acc", {"base": {"k": 0.05}}),
    "accel": ControllerUnderTest.registered("microaccel", "accel", {"k": 0.05}),
}
REPOSITORY = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class TrainingRun:
    """What `run_training` wrote."""

    policy_path: Path
    manifest_path: Path
    sha256: str
    summary: list[dict[str, Any]]


def source_commit() -> str:
    """The repository's commit, `+dirty` when the work tree differs from it."""
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPOSITORY, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=REPOSITORY,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return commit + ("+dirty" if dirty else "")


def run_training(
    drives: Sequence[Drive],
    config: EnvConfig,
    settings: PpoSettings,
    *,
    timesteps: int,
    seed: int,
    folds: int,
    out_dir: Path,
    final: bool = True,
    reward_candidates: Sequence[RewardWeights] = (),
    recorded: Sequence[RecordedDrive] = (),
    restarts: int = 1,
    command: str = "",
    progress: Callable[[str, int, int], None] | None = None,
) -> TrainingRun:
    """Cross-validate, train the shipped policy, write `rl_<actuation>.npz` and `.json`.

    With `reward_candidates` (the first is the fallback), every fold, and the final policy,
    trains with the weights `select_reward` chooses on its own training dates; without, with
    `config.reward`. Every training also drives the `recorded` drives of its own dates on
    their real INRIX (`train.recorded_on_dates_of`). With `restarts` > 1 every fold's policy and
    the final one are the restart `sim.rl.restarts` keeps on their training drives (the reward
    selection's inner policies are one seed each). `command` is recorded in the manifest (how
    to reproduce it); `progress(stage, done, total)` hears the timesteps of each training and
    each scored drive.
    """
    if restarts < 1:
        raise ValueError(f"restarts must be at least 1, got {restarts}")
    commit = source_commit()  # now: the code that trains, whatever changes meanwhile
    actuation = config.actuation
    name = f"rl_{actuation}"
    splits = date_folds(drives, folds)
    scores: list[DriveScore] = []
    fold_records = []

    def chosen_reward(stage: str, dates: Sequence[Drive]) -> tuple[EnvConfig, dict[str, Any]]:
        """`config` with the reward chosen on `dates` and the selection's record, or as is."""
        if not reward_candidates:
            return config, {}
        selection = select_reward(
            dates,
            config,
            reward_candidates,
            settings,
            timesteps=timesteps,
            seed=seed,
            out_dir=out_dir / "reward_selection" / stage.replace(" ", ""),
            stage=stage,
            progress=progress,
            recorded=recorded,
        )
        return replace(config, reward=selection.chosen), selection.as_dict()

    fold_configs = []
    for fold in splits:
        fold_config, selection_record = chosen_reward(f"fold {fold.index}", fold.train)
        fold_scores, record = _cross_validate(
            fold, fold_config, settings, timesteps, seed, restarts, out_dir, progress, recorded
        )
        scores.extend(fold_scores)
        if selection_record:
            record["reward_selection"] = selection_record
        fold_records.append(record)
        fold_configs.append(fold_config)
    policy_path = out_dir / f"{name}.npz"
    if final:
        shipped_config, final_selection = chosen_reward("final", drives)
        digest, final_restarts = _train_kept_restart(
            drives,
            shipped_config,
            settings,
            timesteps,
            seed,
            restarts,
            policy_path,
            "final",
            progress,
            recorded,
        )
        shipped_dates = sorted({drive_date(drive) for drive in drives})
        shipped = "trained on every date"
        shipped_recorded = recorded_on_dates_of(recorded, drives)
    else:
        shipped_config, final_selection = fold_configs[0], {}
        final_restarts = fold_records[0].get("restarts", {})
        shutil.copyfile(_fold_path(out_dir, name, 0), policy_path)
        digest = hashlib.sha256(policy_path.read_bytes()).hexdigest()
        shipped_dates = splits[0].train_dates
        shipped = "fold 0's policy"
        shipped_recorded = recorded_on_dates_of(recorded, splits[0].train)
    summary = summarise(scores)
    manifest = {
        "policy": policy_path.name,
        "sha256": digest,
        "actuation": actuation,
        "shipped": shipped,
        "training_dates": shipped_dates,
        # manifests of policies trained on simulated INRIX alone have no such key
        **(
            {"recorded_inrix_drives": [one.drive.name for one in shipped_recorded]}
            if recorded
            else {}
        ),
        "seed": seed,
        "timesteps": timesteps,
        # what each training took (whole rollouts); manifests before 2026-12-04 have no such key
        "timesteps_trained": settings.trained_timesteps(timesteps),
        # manifests of policies trained from one seed have no such key
        **({"restarts": final_restarts} if final_restarts else {}),
        "folds": folds,
        "ppo": settings.as_dict(),
        "environment": _config_record(shipped_config),
        "source_commit": commit,
        "command": command,
        "trained_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "versions": {
            "python": platform.python_version(),
            "torch": torch.__version__,
            "stable_baselines3": stable_baselines3.__version__,
        },
        "cross_validation": {
            "note": "every figure is on dates held out of the policy that produced it",
            "summary": summary,
            "folds": fold_records,
            "drives": [score.as_dict() for score in scores],
        },
    }
    if reward_candidates:
        manifest["reward_selection"] = {
            "candidates": [asdict(weights) for weights in reward_candidates],
            "note": "each fold chose on its training dates alone (inner folds by date)",
            **({"final": final_selection} if final_selection else {}),
        }
    manifest_path = out_dir / f"{name}.json"
    manifest_path.write_text(json.dumps(without_nan(manifest), indent=2, allow_nan=False) + "\n")
    return TrainingRun(policy_path, manifest_path, digest, summary)


def without_nan(value: Any) -> Any:
    """`value` with every NaN or infinite float as None (JSON null). A KPI the baseline cannot
    measure on a folder's drives is NaN; written as Python writes it, the manifest is no JSON
    and the server refuses to store it (`app.policies.service.read_manifest`)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {key: without_nan(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [without_nan(item) for item in value]
    return value


def _fold_path(out_dir: Path, name: str, index: int) -> Path:
    return out_dir / "folds" / f"{name}_fold{index}.npz"


def _train_kept_restart(
    drives: Sequence[Drive],
    config: EnvConfig,
    settings: PpoSettings,
    timesteps: int,
    seed: int,
    restarts: int,
    path: Path,
    stage: str,
    progress: Callable[[str, int, int], None] | None,
    recorded: Sequence[RecordedDrive],
) -> tuple[str, dict[str, Any]]:
    """Train on `drives` from seeds seed, seed + 1, ... (`restarts` of them), write the restart
    `sim.rl.restarts` keeps to `path`; its sha256 and, with more than one restart, the record
    of every restart's scores on its training drives (an empty record with one)."""
    if restarts == 1:
        model = train_policy(
            drives,
            config,
            settings,
            timesteps,
            seed,
            stage_progress(progress, stage, timesteps),
            recorded,
        )
        return export_policy(model, path, config), {}
    scored = []
    for restart in range(restarts):
        restart_seed = seed + restart
        label = f"{stage} restart {restart}"
        model = train_policy(
            drives,
            config,
            settings,
            timesteps,
            restart_seed,
            stage_progress(progress, label, timesteps),
            recorded,
        )
        restart_path = path.with_name(f"{path.stem}_seed{restart_seed}{path.suffix}")
        export_policy(model, restart_path, config)
        policy = ControllerUnderTest.policy_file(
            f"rl_{config.actuation}", config.actuation, restart_path
        )
        scores = score_drives(
            drives,
            [policy],
            planner=config.planner,
            planner_params=config.planner_params,
            bounds=config.gap_bounds,
            cut_ins=config.cut_ins,
            progress=scoring_progress(progress, f"{label} training drives", len(drives)),
        )
        scored.append((restart_path, RestartScores(restart_seed, tuple(scores))))
    kept = choose_restart([restart for _, restart in scored])
    shutil.copyfile(scored[kept][0], path)
    record = {
        "kept_seed": scored[kept][1].seed,
        "rule": (
            "fewest collisions, then fewest takeovers, then the least mean distance lost, on "
            "the training drives"
        ),
        "restarts": [restart.as_dict() for _, restart in scored],
    }
    return hashlib.sha256(path.read_bytes()).hexdigest(), record


def _cross_validate(
    fold: Fold,
    config: EnvConfig,
    settings: PpoSettings,
    timesteps: int,
    seed: int,
    restarts: int,
    out_dir: Path,
    progress: Callable[[str, int, int], None] | None,
    recorded: Sequence[RecordedDrive],
) -> tuple[list[DriveScore], dict[str, Any]]:
    """Train on the fold's dates (and the recorded drives of those dates; the restart kept on
    them), score on its held-out dates beside the reference."""
    actuation = config.actuation
    name = f"rl_{actuation}"
    stage = f"fold {fold.index}"
    path = _fold_path(out_dir, name, fold.index)
    digest, restart_record = _train_kept_restart(
        fold.train, config, settings, timesteps, seed, restarts, path, stage, progress, recorded
    )
    tested = [
        ControllerUnderTest.policy_file(name, actuation, path),
        REFERENCES[actuation],
    ]
    scores = score_drives(
        fold.held_out,
        tested,
        planner=config.planner,
        planner_params=config.planner_params,
        bounds=config.gap_bounds,  # the envelope the policy was trained to keep, as recorded
        cut_ins=config.cut_ins,  # the cars that merged in training merge here too
        progress=scoring_progress(progress, f"{stage} held-out", len(fold.held_out) * len(tested)),
    )
    record = {
        "fold": fold.index,
        "train_dates": fold.train_dates,
        "held_out_dates": fold.held_out_dates,
        **(
            {
                "recorded_inrix_drives": [
                    one.drive.name for one in recorded_on_dates_of(recorded, fold.train)
                ]
            }
            if recorded
            else {}
        ),
        **({"restarts": restart_record} if restart_record else {}),
        "policy_sha256": digest,
        "held_out": summarise(scores),
    }
    return scores, record


def _config_record(config: EnvConfig) -> Mapping[str, Any]:
    # Recorded only when not the plain request or the radar observation, as in the policy file:
    # the manifests of policies trained before either existed reproduce unchanged.
    action = {"accel_action": config.accel_action} if config.accel_action != "request" else {}
    observation = (
        {"accel_observation": config.accel_observation}
        if config.accel_observation != "radar"
        else {}
    )
    return {
        **action,
        **observation,
        "humans": config.humans,
        "episode_s": config.episode_s,
        "planner": config.planner,
        "planner_params": dict(config.planner_params),
        "reward": asdict(config.reward),
        "gap_bounds": {
            "min_gap_m": config.gap_bounds.min_gap_m,
            "max_gap_m": config.gap_bounds.max_gap_m,
            "min_time_gap_s": config.gap_bounds.min_time_gap_s,
        },
        # manifests written before cut-ins were trained with have no such key
        "cut_ins": None
        if config.cut_ins is None
        else {
            "accept_time_gap_s": config.cut_ins.accept_time_gap_s,
            "rate_per_s_per_s": config.cut_ins.rate_per_s_per_s,
            "min_gap_m": config.cut_ins.min_gap_m,
        },
    }
