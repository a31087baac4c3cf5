"""The held-out scores' summary per group of drives."""

from __future__ import annotations

import math

from sim.rl.scores import summarise
from tests.sim.rl.test_reward_selection import score


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
