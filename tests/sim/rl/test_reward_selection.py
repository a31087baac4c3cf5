"""Choosing the reward weights inside a fold: the candidates, the bounds, the choice, the run."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from sim.drives import load_drive
from sim.rl.env import RewardWeights
from sim.rl.reward_selection import (
    RewardCandidateError,
    admissibility,
    choose,
    parse_reward_candidates,
    ranking_fuel_saving_pct,
)
from sim.rl.scores import DriveScore
from tests.sim.rl.test_train import FREEFLOW, train_accel
from tests.sim.test_evaluate import write_drive


def score(
    kind: str,
    fuel: float,
    *,
    throughput: float = 0.0,
    speed: float = 0.0,
    collisions: int = 0,
    takeovers: int = 0,
    within: float = 1.0,
    stop_and_go: bool = False,
    unmeasured: str = "",
) -> DriveScore:
    return DriveScore(
        drive=f"2021-04-05-{kind}",
        date="2021-04-05",
        kind=kind,
        stop_and_go=stop_and_go,
        controller="rl_accel",
        fuel_saving_pct=fuel,
        throughput_change_pct=throughput,
        network_speed_change_pct=speed,
        accel_rms_change_pct=0.0,
        collisions=collisions,
        takeovers=takeovers,
        gap_within_share=within,
        unmeasured_by_baseline=unmeasured,
    )


def test_candidates_start_with_the_defaults_and_change_one_weight_each() -> None:
    candidates = parse_reward_candidates('[{"fuel": 0.6}, {"accel": 0.3, "speed": 0}]')
    assert candidates[0] == RewardWeights()
    assert candidates[1] == RewardWeights(fuel=0.6)
    assert candidates[2] == RewardWeights(accel=0.3, speed=0.0)


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("[{fuel: 1}]", "not JSON"),
        ("{}", "non-empty JSON list"),
        ("[]", "non-empty JSON list"),
        ('[{"fule": 0.6}]', "names fule: the weights are accel, collision, fuel, gap, speed"),
        ('[{"fuel": -1}]', "fuel must be finite and >= 0, got -1"),
        ('[{"fuel": "high"}]', "fuel must be a number, got 'high'"),
        ('[{"fuel": 0.2}]', "repeats an earlier one"),
        ("[1]", "must be an object of weights"),
    ],
)
def test_a_bad_candidate_says_what_is_wrong(text: str, says: str) -> None:
    with pytest.raises(RewardCandidateError, match=says):
        parse_reward_candidates(text)


def test_admissibility_names_every_broken_bound() -> None:
    assert admissibility([score("shockwave", 3.0), score("freeflow", 0.0)]) == []
    broken = admissibility(
        [
            score("shockwave", 3.0, throughput=-2.5, collisions=1),
            score("freeflow", 0.0, speed=-1.5, within=0.97, takeovers=2),
        ]
    )
    assert broken == [
        "shockwave throughput -2.50 % < -2 %",
        "freeflow network speed -1.50 % < -1 %",
        "1 collision(s)",
        "2 takeover(s)",
        "within the envelope 98.5 % < 99 %",
    ]
    # the hand-back turns a stop the AV could not make into its driver's: a candidate that
    # needed its driver is no more admissible than one that collided was
    needing_its_driver = [score("shockwave", 9.0, takeovers=12), score("freeflow", 0.0)]
    assert choose([[score("shockwave", 1.0)], needing_its_driver]) == 0
    # the stop-and-go drives are a group of their own (a -2 % floor), freeflow's is -1 %
    assert admissibility([score("shockwave", 3.0, speed=-1.5, stop_and_go=True)]) == []


def test_the_admissible_candidate_saving_most_on_shockwave_drives_is_chosen() -> None:
    defaults = [score("shockwave", 1.0), score("freeflow", 0.0)]
    saves_more = [score("shockwave", 2.0), score("freeflow", -0.5)]
    saves_most_by_falling_back = [score("shockwave", 9.0, throughput=-4.0), score("freeflow", 0.0)]
    assert choose([defaults, saves_more, saves_most_by_falling_back]) == 1
    # none admissible, or a tie: the first candidate (the defaults) stays
    assert choose([saves_most_by_falling_back, saves_most_by_falling_back]) == 0
    assert choose([defaults, list(defaults)]) == 0


def test_a_candidate_that_leaves_a_bound_undefined_is_not_admissible() -> None:
    # it stalled the platoon on a drive whose all-human platoon gives a throughput
    stalled = [score("shockwave", 12.0, throughput=math.nan), score("freeflow", 0.0)]
    assert admissibility(stalled) == ["shockwave throughput undefined"]
    assert choose([[score("shockwave", 1.0), score("freeflow", 0.0)], stalled]) == 0


def test_a_drive_the_all_human_platoon_cannot_measure_counts_for_no_candidate() -> None:
    # a drive too short for the platoon's tail to pass where the leader started: every
    # candidate's throughput and fuel saving there are undefined, through no fault of its own
    short = score(
        "shockwave", math.nan, throughput=math.nan, unmeasured="fuel_economy_mpg;throughput_vph"
    )
    defaults = [score("shockwave", 1.0), short]
    saves_more = [score("shockwave", 2.0), short]
    assert admissibility(defaults) == admissibility(saves_more) == []
    assert ranking_fuel_saving_pct(saves_more) == 2.0
    assert choose([defaults, saves_more]) == 1


@pytest.mark.slow
def test_cli_train_chooses_the_reward_inside_each_fold(shared_dir: Path, tmp_path: Path) -> None:
    drives = tmp_path / "drives"
    drives.mkdir()
    fast = load_drive(shared_dir / FREEFLOW)
    # four dates: each outer fold trains on two, which the selection splits one against one
    for index, name in enumerate(("2021-03-09-a", "2021-03-15-a", "2021-04-05-a", "2021-04-19-a")):
        write_drive(fast.slice(110.0 * index, 120.0), drives / f"{name}.csv")
    out = tmp_path / "out"
    result = train_accel(
        drives,
        out,
        "--timesteps",
        "512",
        "--seed",
        "5",
        "--num-envs",
        "4",
        "--humans",
        "4",
        "--episode-s",
        "60",
        "--reward-candidates",
        '[{"fuel": 0.6}]',
    )
    assert result.returncode == 0, result.stderr
    manifest = json.loads((out / "rl_accel.json").read_text())
    assert manifest["reward_selection"]["candidates"] == [
        {"accel": 0.1, "speed": 0.005, "fuel": 0.2, "gap": 1.0, "collision": 1.0},
        {"accel": 0.1, "speed": 0.005, "fuel": 0.6, "gap": 1.0, "collision": 1.0},
    ]
    for fold in manifest["cross_validation"]["folds"]:
        selection = fold["reward_selection"]
        inner_dates = set()
        for inner in selection["inner_folds"]:
            assert not set(inner["train_dates"]) & set(inner["held_out_dates"])
            inner_dates |= set(inner["train_dates"]) | set(inner["held_out_dates"])
        # the selection read the fold's training dates and nothing of its held-out ones
        assert inner_dates == set(fold["train_dates"])
        for candidate in selection["candidates"]:
            assert {row["date"] for row in candidate["drives"]} == inner_dates
            assert candidate["admissible"] == (not candidate["broken"])
    # the shipped policy trained on every date, with the weights chosen across all of them
    final = manifest["reward_selection"]["final"]
    assert {date for inner in final["inner_folds"] for date in inner["held_out_dates"]} == {
        "2021-03-09",
        "2021-03-15",
        "2021-04-05",
        "2021-04-19",
    }
    assert manifest["shipped"] == "trained on every date"
    assert manifest["environment"]["reward"] == final["chosen"]


def test_cli_train_refuses_a_bad_candidate_before_training(
    shared_dir: Path, tmp_path: Path
) -> None:
    drives = tmp_path / "drives"
    drives.mkdir()
    write_drive(load_drive(shared_dir / FREEFLOW).slice(0.0, 120.0), drives / "2021-03-09-a.csv")
    refused = train_accel(drives, tmp_path / "out", "--reward-candidates", '[{"fule": 0.6}]')
    assert refused.returncode != 0
    assert "--reward-candidates" in refused.stderr
    assert "names fule" in refused.stderr
    assert "Traceback" not in refused.stderr
    assert not (tmp_path / "out").exists()


def test_a_fold_with_one_training_date_cannot_choose(shared_dir: Path, tmp_path: Path) -> None:
    drives = tmp_path / "drives"
    drives.mkdir()
    fast = load_drive(shared_dir / FREEFLOW)
    for index, name in enumerate(("2021-03-09-a", "2021-04-05-a")):
        write_drive(fast.slice(110.0 * index, 120.0), drives / f"{name}.csv")
    refused = train_accel(drives, tmp_path / "out", "--reward-candidates", '[{"fuel": 0.6}]')
    assert refused.returncode != 0
    assert "the reward selection of fold 0 splits its training dates in 2 by date" in (
        refused.stderr
    )
    assert "it trains on 1 (2021-04-05)" in refused.stderr
    assert "Traceback" not in refused.stderr
