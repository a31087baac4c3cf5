"""The policies the agent ships: the files their manifests describe, and how they drive."""

from __future__ import annotations

import hashlib
import json
import shlex
from pathlib import Path

import pytest

from sim.av import agent_policy
from sim.drives import load_drive
from sim.emulator.acc import SimulatedAccCar
from sim.energy import RAV4_2019
from sim.gaps import GapBounds, gap_kpis
from sim.kpi import platoon_kpis
from sim.plans import SimulatedPlanner
from sim.platoon import platoon_roles, simulate_platoon
from vehicle_agent.actuators import AccelLimiter, AccelLimits
from vehicle_agent.controllers import AccelCommand, Observation, build_controller
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES

STOP_AND_GO = "data/trajectories/2021-04-05-21-39-05_masterArray_1_9955.csv"


@pytest.mark.parametrize("actuation", ["acc", "accel"])
def test_the_manifest_describes_the_shipped_file(actuation: str) -> None:
    policy = BUNDLED_POLICIES / f"rl_{actuation}.npz"
    manifest = json.loads((BUNDLED_POLICIES / f"rl_{actuation}.json").read_text())
    assert manifest["sha256"] == hashlib.sha256(policy.read_bytes()).hexdigest()
    assert manifest["actuation"] == actuation
    # the command that trains it, with the seed the manifest records
    command = shlex.split(manifest["command"])
    assert command[:3] == ["smoothfleet", "sim", "train"]
    assert command[command.index("--actuation") + 1] == actuation
    assert int(command[command.index("--seed") + 1]) == manifest["seed"]
    # a policy trained on recorded INRIX drove only the recorded drives of its own training
    # dates (the drives' names begin with their date)
    recorded = manifest.get("recorded_inrix_drives", [])
    assert ("--recorded-inrix" in command) == bool(recorded)
    assert {name[:10] for name in recorded} <= set(manifest["training_dates"])
    # the commit that trained it (the policies of 763d9d9 carry "+dirty": an uncommitted edit
    # of bench/agent.py, which training never imports, was in the tree when the run began)
    assert len(manifest["source_commit"].split("+")[0]) == 40
    # every figure is held out: no fold scored a drive of a date it trained on, and over the
    # folds every date was held out once
    folds = manifest["cross_validation"]["folds"]
    for fold in folds:
        assert not set(fold["train_dates"]) & set(fold["held_out_dates"])
    every_date = set(folds[0]["train_dates"]) | set(folds[0]["held_out_dates"])
    assert {row["date"] for row in manifest["cross_validation"]["drives"]} == every_date
    assert set(manifest["training_dates"]) < every_date


def test_the_acc_policy_s_reward_was_chosen_inside_its_fold() -> None:
    """rl_acc's manifest comes from `sim train --reward-candidates`: each fold chose its weights
    on inner folds of its own training dates, and the shipped (fold 0's) policy trained with
    fold 0's choice."""
    manifest = json.loads((BUNDLED_POLICIES / "rl_acc.json").read_text())
    assert "--reward-candidates" in manifest["command"]
    assert manifest["shipped"] == "fold 0's policy"
    for fold in manifest["cross_validation"]["folds"]:
        selection = fold["reward_selection"]
        read = set()
        for inner in selection["inner_folds"]:
            read |= set(inner["train_dates"]) | set(inner["held_out_dates"])
        assert read == set(fold["train_dates"])
        assert len(selection["candidates"]) == len(manifest["reward_selection"]["candidates"])
    chosen = manifest["cross_validation"]["folds"][0]["reward_selection"]["chosen"]
    assert manifest["environment"]["reward"] == chosen


@pytest.mark.slow
@pytest.mark.parametrize(
    ("actuation", "within_bounds"),
    [
        # measured 0.47: the acc policy drops back up to 263 m behind the leader (a weakness
        # of this 300k-step policy, docs/simulation.md), and saves 19.6 % of fuel doing so
        ("acc", 0.45),
        # measured 0.88: closer than 7 m in the queues (a_safe's standstill gap is 5 m)
        ("accel", 0.85),
    ],
)
def test_the_shipped_policy_drives_a_real_stop_and_go_drive_without_collision(
    shared_dir: Path, actuation: str, within_bounds: float
) -> None:
    drive = load_drive(shared_dir / STOP_AND_GO).slice(300.0, 300.0)
    humans = simulate_platoon(drive, platoon_roles(humans=24, avs=0))
    planner = SimulatedPlanner.for_drive(drive, "kernel_smooth")
    policy = agent_policy(
        f"rl_{actuation}",
        actuation,
        planner,
        stock_acc=SimulatedAccCar() if actuation == "acc" else None,
    )
    mixed = simulate_platoon(
        drive,
        platoon_roles(humans=24, avs=1),
        [policy],
        av_max_accel=lambda v: float(RAV4_2019.max_accel_mps2(v)),
    )
    assert mixed.collisions == 0
    envelope = gap_kpis(
        mixed.gap_m[:, :1],
        mixed.speed_mps[:, 1:2],
        mixed.position_m[:, 1:2],
        mixed.dt_s,
        GapBounds(),
    )
    assert envelope.within_bounds_share >= within_bounds
    # less fuel per distance than the all-human platoon behind the same drive
    assert platoon_kpis(mixed).fuel_economy_mpg > platoon_kpis(humans).fuel_economy_mpg


def test_rl_accel_alone_on_the_road_stays_under_the_fleets_top_speed() -> None:
    """With nothing in radar range the shipped rl_accel asks to accelerate whatever the plan's
    target (+0.1 to +0.5 m/s^2 here): alone on the road it drove on past 150 mph within two
    minutes. The agent's limiter, between it and the car, holds it at the fleet's top speed."""
    controller = build_controller("rl_accel", "accel", {})
    limiter = AccelLimiter()
    limiter.reset(0.0, 0.0)
    speed, top = 29.0, AccelLimits().top_speed_mps
    highest = speed
    for step in range(1200):  # 120 s at the controller's 10 Hz
        time_s = step * 0.1
        action = controller.step(Observation(time_s=time_s, speed_mps=speed, target_speed_mps=29.0))
        assert isinstance(action, AccelCommand)
        assert action.accel_mps2 > 0.0  # it never asks to slow to the plan's 65 mph
        speed += limiter.limit(time_s, action.accel_mps2, speed_mps=speed) * 0.1
        highest = max(highest, speed)
    assert highest <= top
    assert speed == pytest.approx(top, abs=0.05)
