"""The held-out scores' summary per group of drives."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import pytest

from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS
from sim.drives import load_drive
from sim.evaluate import ControllerVariant, run_case
from sim.platoon import CutIns, platoon_roles, simulate_platoon
from sim.rl.env import DEFAULT_PLANNER_PARAMS
from sim.rl.scores import ControllerUnderTest, score_drives, simulate_one_av, summarise
from sim.scenarios import Case
from tests.sim.rl.test_reward_selection import score
from tests.sim.test_evaluate import STOP_AND_GO


def test_a_drive_the_controller_left_undefined_leaves_the_group_figure_undefined() -> None:
    # in any order of the drives
    measured = score("freeflow", 1.0, throughput=-26.1, speed=-3.0)
    unmeasured = score("freeflow", 2.0, throughput=math.nan, speed=-1.0)
    for scores in ([measured, unmeasured], [unmeasured, measured]):
        [row] = summarise(scores)
        assert math.isnan(row["throughput_change_pct"])
        assert math.isnan(row["worst_throughput_change_pct"])
        assert row["worst_network_speed_change_pct"] == -3.0
        assert row["fuel_saving_pct"] == 1.5


def test_a_drive_the_all_human_platoon_cannot_measure_is_left_out_of_that_kpis_figures() -> None:
    measured = score("freeflow", 1.0, throughput=-26.1, speed=-3.0)
    short = score(
        "freeflow",
        math.nan,
        throughput=math.nan,
        speed=-1.0,
        unmeasured="fuel_economy_mpg;throughput_vph",
    )
    for scores in ([measured, short], [short, measured]):
        [row] = summarise(scores)
        assert row["drives"] == 2
        assert row["fuel_saving_pct"] == 1.0
        assert row["throughput_change_pct"] == -26.1
        assert row["worst_throughput_change_pct"] == -26.1
        # the baseline measures network speed on both drives: both count
        assert row["network_speed_change_pct"] == -2.0
        assert row["worst_network_speed_change_pct"] == -3.0
    # no drive of the group measured: no figure
    [row] = summarise([short])
    assert math.isnan(row["throughput_change_pct"])
    assert math.isnan(row["worst_throughput_change_pct"])


def test_scores_say_how_far_behind_the_av_ended_with_the_cut_ins_of_training(
    shared_dir: Path,
) -> None:
    """Distance lost is the human's final position in the all-human platoon minus the AV's in
    its own, as `sim evaluate` reads it; with cut-ins both platoons meet them. microaccel
    (k = 0.05) keeps wide gaps on a stop-and-go slice, so cars merge in."""
    drive = replace(
        load_drive(shared_dir / "data" / STOP_AND_GO).slice(300.0, 300.0), name="2021-04-05-a"
    )
    reference = ControllerUnderTest.registered("microaccel", "accel", {"k": 0.05})
    settings = {"planner": "kernel_smooth", "planner_params": DEFAULT_PLANNER_PARAMS}
    for cut_ins in (None, CutIns()):
        [scored] = score_drives([drive], [reference], humans=4, cut_ins=cut_ins, **settings)
        base = simulate_platoon(drive, platoon_roles(5, 0), cut_ins=cut_ins)
        run = simulate_one_av(drive, reference, humans=4, cut_ins=cut_ins, **settings)
        assert (run.cut_ins > 0) == (cut_ins is not None)
        # the AV is column 1 of both platoons
        expected = float(base.position_m[-1, 1] - run.position_m[-1, 1])
        assert scored.distance_lost_m == pytest.approx(expected)
        assert scored.distance_lost_m > 0.0  # its wide gaps leave it behind the human
    for row in summarise([scored]):  # its groups: stop-and-go and shockwave
        assert row["distance_lost_m"] == scored.distance_lost_m


def test_training_scores_count_the_takeovers_sim_evaluate_counts(shared_dir: Path) -> None:
    """The scores that choose restarts and reward weights ran with no hand-back: rl_acc on the
    2021-04-05 stop-and-go drive closed to 1.2 m of its leader and scored no takeover, where
    `sim evaluate`'s agent handed the car back to its driver twice."""
    drive = load_drive(shared_dir / "data" / STOP_AND_GO)
    rl_acc = ControllerUnderTest.registered("rl_acc", "acc", {})
    planner = {"planner": RECOMMENDED_PLANNER, "planner_params": RECOMMENDED_PLANNER_PARAMS}
    [scored] = score_drives([drive], [rl_acc], cut_ins=CutIns(), **planner)
    case = Case("shockwave", drive)
    evaluated = run_case(
        case,
        RECOMMENDED_PLANNER,
        ControllerVariant("rl_acc", "acc"),
        humans=24,
        avs=1,
        planner_params=RECOMMENDED_PLANNER_PARAMS,
    )
    assert evaluated.takeovers > 0
    assert scored.takeovers == evaluated.takeovers
    assert scored.driver_seconds == pytest.approx(evaluated.driver_seconds)
    [row, *_] = summarise([scored])
    assert row["takeovers"] == evaluated.takeovers
