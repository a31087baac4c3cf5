"""PPO end to end: a tiny policy trains, exports to the car's format and is scored held out."""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sim.drives import Drive, drive_from_speeds, load_drive
from sim.gaps import GapBounds
from sim.rl.env import EnvConfig
from sim.rl.pipeline import run_training, without_nan
from sim.rl.scores import ControllerUnderTest
from sim.rl.train import PpoSettings, export_policy, train_policy
from tests.sim.test_evaluate import write_drive
from tests.support.servers import cli_env, run_cli
from vehicle_agent.controllers import Observation
from vehicle_agent.controllers.policy import load_policy

STOP_AND_GO = "data/trajectories/2021-04-05-21-39-05_masterArray_1_9955.csv"
FREEFLOW = "data/trajectories/2021-03-09-13-35-04_masterArray_0_4633.csv"
RECORDED = Path(
    "data/trajectories_with_inrix/2021-03-09-13-35-04_2T3MWRFVXLW056972_masterArray_0_6825"
)
TINY = PpoSettings(num_envs=4, n_steps=128, batch_size=256, n_epochs=2)


def train_accel(drives: Path, out: Path, *options: str) -> subprocess.CompletedProcess[str]:
    """`smoothfleet sim train --actuation accel` on the drives in `drives`, writing to `out`."""
    return run_cli(
        "sim",
        "train",
        "--actuation",
        "accel",
        "--drives",
        str(drives),
        "--out",
        str(out),
        *options,
        env=cli_env(),
        timeout=400,
    )


def stop_and_go(shared_dir: Path) -> Drive:
    return load_drive(shared_dir / STOP_AND_GO).slice(300.0, 200.0)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("actuation", "observation", "inputs"),
    [("acc", "radar", 6), ("accel", "radar", 6), ("accel", "commanded_accel", 7)],
)
def test_a_tiny_policy_trains_and_the_car_runs_exactly_its_actions(
    shared_dir: Path, tmp_path: Path, actuation: str, observation: str, inputs: int
) -> None:
    config = EnvConfig(
        "acc" if actuation == "acc" else "accel",
        accel_observation="commanded_accel" if observation == "commanded_accel" else "radar",
        humans=4,
        episode_s=60.0,
    )
    seen: list[int] = []
    model = train_policy([stop_and_go(shared_dir)], config, TINY, 2000, 7, seen.append)
    # PPO trains whole rollouts: what it took, as the manifest records it
    assert model.num_timesteps == TINY.trained_timesteps(2000) > 2000
    assert seen[-1] == model.num_timesteps
    path = tmp_path / f"rl_{actuation}.npz"
    digest = export_policy(model, path, config)
    assert digest == hashlib.sha256(path.read_bytes()).hexdigest()
    network = load_policy(path, config.actuation)
    assert network.accel_observation == observation
    features = np.random.default_rng(0).uniform(-1.0, 1.5, size=(64, inputs))
    expected, _ = model.predict(features, deterministic=True)
    np.testing.assert_allclose(network.action(features), expected, atol=1e-5)
    # the controller the scores run reads the same file
    controller = ControllerUnderTest.policy_file("rl", actuation, path).build()
    controller.step(
        Observation(time_s=0.0, speed_mps=20.0, target_speed_mps=22.0, commanded_accel_mps2=0.5)
    )


@pytest.mark.slow
def test_cli_train_cross_validates_by_date_and_writes_the_manifest(
    shared_dir: Path, tmp_path: Path
) -> None:
    drives = tmp_path / "drives"
    drives.mkdir()
    fast = load_drive(shared_dir / FREEFLOW)
    # three dates, one of them recorded twice (parts of one fast drive: 25 cars pass 3.6 km)
    for name, drive in (
        ("2021-04-05-a", fast.slice(0.0, 120.0)),
        ("2021-04-05-b", fast.slice(110.0, 120.0)),
        ("2021-03-09-a", fast.slice(220.0, 120.0)),
        ("2021-04-19-a", fast.slice(330.0, 120.0)),
    ):
        write_drive(drive, drives / f"{name}.csv")
    # one drive recorded with its INRIX minutes, on 2021-03-09: fold 1 trains on that date
    recorded = tmp_path / "inrix"
    shutil.copytree(shared_dir / RECORDED, recorded / RECORDED.name)
    out = tmp_path / "out"
    result = train_accel(
        drives,
        out,
        "--recorded-inrix",
        "--inrix-drives",
        str(recorded),
        "--timesteps",
        "1024",
        "--seed",
        "5",
        "--num-envs",
        "4",
        "--gamma",
        "0.99",
        "--humans",
        "4",
        "--episode-s",
        "60",
        "--accel-observation",
        "commanded_accel",
        "--restarts",
        "2",
        "--no-final",
    )
    assert result.returncode == 0, result.stderr
    manifest = json.loads((out / "rl_accel.json").read_text())
    assert manifest["environment"]["accel_observation"] == "commanded_accel"
    assert load_policy(out / "rl_accel.npz", "accel").accel_observation == "commanded_accel"
    assert manifest["sha256"] == hashlib.sha256((out / "rl_accel.npz").read_bytes()).hexdigest()
    assert manifest["seed"] == 5
    assert (manifest["timesteps"], manifest["timesteps_trained"]) == (1024, 1024)  # 4 x 256
    assert manifest["ppo"]["num_envs"] == 4
    assert manifest["ppo"]["gamma"] == 0.99
    assert manifest["command"].startswith("smoothfleet sim train --actuation accel")
    assert manifest["environment"]["gap_bounds"] == {
        "min_gap_m": 7.0,
        "max_gap_m": 120.0,
        "min_time_gap_s": 1.0,
    }
    # trained with cars merging into the AV's gap, as sim evaluate has them
    assert manifest["environment"]["cut_ins"] == {
        "accept_time_gap_s": 3.0,
        "rate_per_s_per_s": 0.1,
        "min_gap_m": 19.0,
    }
    folds = manifest["cross_validation"]["folds"]
    assert [fold["held_out_dates"] for fold in folds] == [
        ["2021-03-09", "2021-04-19"],
        ["2021-04-05"],
    ]
    for fold in folds:
        assert not set(fold["train_dates"]) & set(fold["held_out_dates"])
    # each fold trained seeds 5 and 6 and kept the one the rule keeps on its training drives
    for fold in folds:
        restarts = fold["restarts"]["restarts"]
        assert [restart["seed"] for restart in restarts] == [5, 6]
        kept = fold["restarts"]["kept_seed"]
        ranked = min(restarts, key=lambda r: (r["collisions"], r["mean_distance_lost_m"]))
        assert kept == ranked["seed"]
        kept_file = out / "folds" / f"rl_accel_fold{fold['fold']}_seed{kept}.npz"
        assert fold["policy_sha256"] == hashlib.sha256(kept_file.read_bytes()).hexdigest()
    assert manifest["restarts"] == folds[0]["restarts"]
    # each fold drove the recorded drive on its real feed only where it trained on its date
    assert [fold["recorded_inrix_drives"] for fold in folds] == [[], [RECORDED.name]]
    assert manifest["recorded_inrix_drives"] == []
    # fold 0's policy is shipped: trained on fold 0's dates only
    assert manifest["shipped"] == "fold 0's policy"
    assert manifest["training_dates"] == ["2021-04-05"]
    scored = {(row["drive"], row["controller"]) for row in manifest["cross_validation"]["drives"]}
    assert len(scored) == 8  # 4 drives x (rl_accel, microaccel), each on its held-out fold
    assert "rl_accel" in result.stdout
    assert "cut-ins as in training, no hand-backs: sim select and sim evaluate" in " ".join(
        result.stdout.split()
    )
    assert "distance lost " in result.stdout
    assert "to the reachable leader >= " in result.stdout
    assert "sha256" in result.stdout


@pytest.mark.slow
def test_held_out_scores_judge_the_envelope_the_policy_was_trained_to_keep(
    shared_dir: Path, tmp_path: Path
) -> None:
    """The manifest records the training's gap bounds; its held-out "gap within" share must be
    against the same bounds. No AV keeps a gap of 0-1 m: every share is 0 with those bounds
    (the default 7-120 m envelope gave 1.0 on these slices)."""
    fast = load_drive(shared_dir / FREEFLOW)
    drives = [
        replace(fast.slice(start, 120.0), name=name)
        for name, start in (("2021-04-05-a", 0.0), ("2021-03-09-a", 220.0))
    ]
    bounds = GapBounds(min_gap_m=0.0, max_gap_m=1.0, min_time_gap_s=0.0)
    config = EnvConfig("accel", humans=4, episode_s=60.0, gap_bounds=bounds, cut_ins=None)
    run = run_training(
        drives, config, TINY, timesteps=512, seed=3, folds=2, out_dir=tmp_path, final=False
    )
    manifest = json.loads(run.manifest_path.read_text())
    assert manifest["environment"]["gap_bounds"]["max_gap_m"] == 1.0
    assert manifest["environment"]["cut_ins"] is None  # trained without cut-ins, and says so
    shares = {row["gap_within_share"] for row in manifest["cross_validation"]["drives"]}
    assert shares == {0.0}
    # judged to the reachable leader too, never less often within
    rows = manifest["cross_validation"]["drives"]
    assert all(row["gap_within_share"] <= row["gap_within_reachable_share"] <= 1.0 for row in rows)


def test_a_kpi_not_measured_is_written_as_null_not_nan() -> None:
    """NaN in a manifest is no JSON, and the server refused to store it (policy audit)."""
    manifest = {"kpi": float("nan"), "folds": [{"fuel": float("inf"), "n": 3}], "note": "x"}
    assert json.loads(json.dumps(without_nan(manifest), allow_nan=False)) == {
        "kpi": None,
        "folds": [{"fuel": None, "n": 3}],
        "note": "x",
    }


def test_cli_train_names_a_missing_folder(tmp_path: Path) -> None:
    missing = run_cli(
        "sim", "train", "--actuation", "acc", "--drives", str(tmp_path / "x"), env=cli_env()
    )
    assert missing.returncode != 0
    assert "no drive CSV files" in missing.stderr
    assert "Traceback" not in missing.stderr


def test_cli_train_refuses_an_accel_observation_for_an_acc_policy(tmp_path: Path) -> None:
    drives = tmp_path / "drives"
    drives.mkdir()
    write_drive(drive_from_speeds("2021-04-05-a", np.full(100, 20.0)), drives / "2021-04-05-a.csv")
    refused = run_cli(
        "sim",
        "train",
        "--actuation",
        "acc",
        "--accel-observation",
        "commanded_accel",
        "--drives",
        str(drives),
        "--out",
        str(tmp_path / "out"),
        env=cli_env(),
    )
    assert refused.returncode != 0
    assert "observation 'commanded_accel' is for accel policies, not acc" in refused.stderr
    assert "Traceback" not in refused.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_the_final_policy_is_the_restart_kept_on_every_date(
    shared_dir: Path, tmp_path: Path
) -> None:
    """With a final policy, its restarts train on every date and the shipped file is the one
    the rule keeps on them (each fold chooses its own, as the CLI test checks)."""
    fast = load_drive(shared_dir / FREEFLOW)
    drives = [
        replace(fast.slice(start, 120.0), name=name)
        for name, start in (("2021-04-05-a", 0.0), ("2021-03-09-a", 220.0))
    ]
    config = EnvConfig("accel", humans=4, episode_s=60.0)
    run = run_training(
        drives, config, TINY, timesteps=512, seed=3, folds=2, out_dir=tmp_path, restarts=2
    )
    manifest = json.loads(run.manifest_path.read_text())
    final = manifest["restarts"]
    assert [restart["seed"] for restart in final["restarts"]] == [3, 4]
    ranked = min(final["restarts"], key=lambda r: (r["collisions"], r["mean_distance_lost_m"]))
    assert final["kept_seed"] == ranked["seed"]
    kept_file = tmp_path / f"rl_accel_seed{final['kept_seed']}.npz"
    assert run.sha256 == hashlib.sha256(kept_file.read_bytes()).hexdigest()
    assert manifest["shipped"] == "trained on every date"
    with pytest.raises(ValueError, match="restarts must be at least 1"):
        run_training(
            drives, config, TINY, timesteps=512, seed=3, folds=2, out_dir=tmp_path, restarts=0
        )
