"""The held-out scores' summary per group of drives."""

from __future__ import annotations

import math

from sim.rl.scores import summarise
from tests.sim.rl.test_reward_selection import score


def test_a_drive_without_a_measure_leaves_the_group_figure_undefined_in_any_order() -> None:
    measured = score("freeflow", 1.0, throughput=-26.1, speed=-3.0)
    unmeasured = score("freeflow", 2.0, throughput=math.nan, speed=-1.0)
    for scores in ([measured, unmeasured], [unmeasured, measured]):
        [row] = summarise(scores)
        assert math.isnan(row["throughput_change_pct"])
        assert math.isnan(row["worst_throughput_change_pct"])
        assert row["worst_network_speed_change_pct"] == -3.0
        assert row["fuel_saving_pct"] == 1.5
