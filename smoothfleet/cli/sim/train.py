"""`smoothfleet sim train`: the PPO-trained RL controller, cross-validated by date."""

from __future__ import annotations

import math
import shlex
import sys
from dataclasses import replace
from pathlib import Path

import click
from rich.progress import TaskID

from sim.platoon import CutIns
from sim.report import percent_text
from smoothfleet.cli.common import FiniteFloatRange, output_folder
from smoothfleet.cli.sim.shared import (
    console,
    default_folder,
    drives_option,
    progress_bar,
    read_drives,
    read_recorded_drives,
)


def _share_text(share: float) -> str:
    """A share of time in % for people; "n/a" where it is undefined."""
    return f"{100 * share:.1f} %" if math.isfinite(share) else "n/a"


@click.command("train")
@click.option(
    "--actuation",
    type=click.Choice(["acc", "accel"]),
    required=True,
    help="acc: ACC speed setting and gap bars (Rogue, XT5); accel: acceleration (RAV4).",
)
@drives_option("Folder of real drive CSVs (10 Hz) to train and cross-validate on")
@click.option("--timesteps", type=click.IntRange(min=1), default=300_000, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option(
    "--folds",
    type=click.IntRange(min=2),
    default=2,
    show_default=True,
    help="Cross-validation folds; each holds out whole dates.",
)
@click.option(
    "--final/--no-final",
    default=True,
    show_default=True,
    help="Ship a policy trained on every date (else fold 0's policy).",
)
@click.option("--num-envs", type=click.IntRange(1, 256), default=16, show_default=True)
@click.option(
    "--restarts",
    type=click.IntRange(1, 16),
    default=1,
    show_default=True,
    help="Train each policy from this many seeds (--seed, --seed + 1, ...) and keep the one "
    "that drops back least on its own training drives (sim.rl.restarts).",
)
@click.option(
    "--accel-action",
    type=click.Choice(["request", "request_time_margin"]),
    default="request",
    show_default=True,
    help="accel policies: an acceleration request under a_safe, or a request and a time "
    "margin (0-1.5 s) a_safe adds to its gap.",
)
@click.option(
    "--accel-observation",
    type=click.Choice(["radar", "commanded_accel"]),
    default="radar",
    show_default=True,
    help="accel policies: the paper's observation with the radar's gap and relative speed, "
    "or that and the acceleration the agent's limiter last let through.",
)
@click.option(
    "--gamma",
    type=FiniteFloatRange(0.0, 1.0, max_open=True),
    default=None,
    help="PPO's discount per 0.1 s step: how far ahead a reward still counts "
    "[default: PpoSettings', 0.995, about 20 s].",
)
@click.option(
    "--humans",
    type=click.IntRange(1, 200),
    default=24,
    show_default=True,
    help="IDM drivers behind the AV in training.",
)
@click.option("--episode-s", type=FiniteFloatRange(min=1.0), default=300.0, show_default=True)
@click.option(
    "--cut-ins/--no-cut-ins",
    default=True,
    show_default=True,
    help="Cars from the next lane merge into the AV's gap in training, as `sim evaluate` has "
    "them (sim.platoon.CutIns); --no-cut-ins trains as every policy before 2026-12-03 was.",
)
@click.option(
    "--recorded-inrix",
    is_flag=True,
    help="Also train on the drives recorded with their INRIX minutes (--inrix-drives), each "
    "on its real feed, each training only on those of its own dates "
    "[default: every plan from simulated INRIX, as every policy before 2026-12-04 was].",
)
@click.option(
    "--inrix-drives",
    "inrix_dir",
    type=click.Path(path_type=Path),
    default=lambda: default_folder("trajectories_with_inrix"),
    help="Folder of drives recorded with their INRIX minutes, read with --recorded-inrix "
    "[default: shared/data/trajectories_with_inrix beside the checkout].",
)
@click.option(
    "--reward-candidates",
    default=None,
    help='JSON list of reward weight changes, e.g. \'[{"fuel": 0.6}, {"accel": 0.3}]\': '
    "each fold chooses between the defaults and these on its own training dates "
    "(sim.rl.reward_selection) [default: the defaults, no selection].",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(path_type=Path),
    default=Path("policies"),
    show_default=True,
    help="Where rl_<actuation>.npz, its manifest .json and the fold policies go.",
)
def train_command(
    actuation: str,
    drives_dir: Path | None,
    timesteps: int,
    seed: int,
    folds: int,
    final: bool,
    num_envs: int,
    restarts: int,
    accel_action: str,
    accel_observation: str,
    gamma: float | None,
    humans: int,
    episode_s: float,
    cut_ins: bool,
    recorded_inrix: bool,
    inrix_dir: Path | None,
    reward_candidates: str | None,
    out_dir: Path,
) -> None:
    """Train the RL controller with PPO (paper, ACC-Based Controller), cross-validated by date.

    Needs the `train` extra (torch, stable-baselines3, gymnasium).
    """
    if drives_dir is None:
        raise click.ClickException("no shared data found beside the checkout: pass --drives")
    try:
        from sim.rl.env import EnvConfig
        from sim.rl.pipeline import run_training
        from sim.rl.reward_selection import RewardCandidateError, parse_reward_candidates
        from sim.rl.train import PpoSettings
    except ImportError as error:
        raise click.ClickException(
            f"sim train needs the train extra (pip install -e '.[train]'): {error}"
        ) from None
    if recorded_inrix and inrix_dir is None:
        raise click.ClickException(
            "no shared data found beside the checkout: pass --inrix-drives with --recorded-inrix"
        )
    drives = read_drives(drives_dir)
    recorded = read_recorded_drives(inrix_dir) if recorded_inrix and inrix_dir is not None else []
    try:
        config = EnvConfig(
            "acc" if actuation == "acc" else "accel",
            "request_time_margin" if accel_action == "request_time_margin" else "request",
            "commanded_accel" if accel_observation == "commanded_accel" else "radar",
            humans=humans,
            episode_s=episode_s,
            cut_ins=CutIns() if cut_ins else None,
        )
    except ValueError as error:
        raise click.ClickException(str(error)) from None
    try:
        candidates = parse_reward_candidates(reward_candidates) if reward_candidates else []
    except RewardCandidateError as error:
        raise click.BadParameter(str(error), param_hint="--reward-candidates") from None
    settings = PpoSettings(num_envs=num_envs)
    if gamma is not None:
        settings = replace(settings, gamma=gamma)
    if (trained := settings.trained_timesteps(timesteps)) != timesteps:
        console.print(
            f"PPO collects whole rollouts of {settings.n_steps} steps x {settings.num_envs} "
            f"platoons: each training takes {trained:,} steps for --timesteps {timesteps:,} "
            "(the manifest records both)"
        )
    output_folder(out_dir, "--out")
    with progress_bar() as progress:
        tasks: dict[str, TaskID] = {}

        def advance(stage: str, done: int, total: int) -> None:
            if stage not in tasks:
                tasks[stage] = progress.add_task(stage, total=total)
            progress.update(tasks[stage], completed=done)

        try:
            result = run_training(
                drives,
                config,
                settings,
                timesteps=timesteps,
                seed=seed,
                folds=folds,
                out_dir=out_dir,
                final=final,
                reward_candidates=candidates,
                recorded=recorded,
                restarts=restarts,
                command=shlex.join(["smoothfleet", *sys.argv[1:]]),
                progress=advance,
            )
        except ValueError as error:
            raise click.ClickException(str(error)) from None
    console.print(
        "held out (each fold's policy on the dates it was not trained on; one AV behind the "
        "leader, simulated INRIX, cut-ins as in training, no hand-backs: sim select and sim "
        "evaluate, which have them, give the verdict):"
    )
    for row in result.summary:
        console.print(
            f"{row['controller']:>15} {row['group']:>12} ({row['drives']} drives): fuel saving "
            f"{percent_text(row['fuel_saving_pct'])}, throughput "
            f"{percent_text(row['throughput_change_pct'])} (worst "
            f"{percent_text(row['worst_throughput_change_pct'])}), network speed "
            f"{percent_text(row['network_speed_change_pct'])} (worst "
            f"{percent_text(row['worst_network_speed_change_pct'])}), collisions "
            f"{row['collisions']}, gap within bounds >= {100 * row['min_gap_within_share']:.1f} %"
            f" (to the reachable leader >= {_share_text(row['min_gap_within_reachable_share'])})"
            f", distance lost {row['distance_lost_m']:+.0f} m"
        )
    console.print(
        f"wrote {result.policy_path} (sha256 {result.sha256[:12]}) and {result.manifest_path}"
    )
