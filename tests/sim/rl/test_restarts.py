"""The restart rule: fewest collisions, then fewest takeovers, then the least distance lost, on the
training drives."""

from __future__ import annotations

import math

import pytest

from sim.rl.restarts import RestartChoiceError, RestartScores, choose_restart
from sim.rl.scores import DriveScore


def score(distance_lost_m: float, collisions: int = 0, takeovers: int | None = 0) -> DriveScore:
    return DriveScore(
        drive="2021-04-05-a",
        date="2021-04-05",
        kind="shockwave",
        stop_and_go=True,
        controller="rl_accel",
        fuel_saving_pct=1.0,
        throughput_change_pct=0.0,
        network_speed_change_pct=0.0,
        accel_rms_change_pct=0.0,
        collisions=collisions,
        gap_within_share=1.0,
        distance_lost_m=distance_lost_m,
        takeovers=takeovers,
    )


def restart(seed: int, *scores: DriveScore) -> RestartScores:
    return RestartScores(seed, scores)


def test_the_restart_that_drops_back_least_is_kept() -> None:
    # means: seed 13 (100 + 20) / 2 = 60 m, seed 14 (30 + 40) / 2 = 35 m, seed 15 50 m
    restarts = [
        restart(13, score(100.0), score(20.0)),
        restart(14, score(30.0), score(40.0)),
        restart(15, score(50.0), score(50.0)),
    ]
    assert choose_restart(restarts) == 1
    assert restarts[1].as_dict() == {
        "seed": 14,
        "collisions": 0,
        "takeovers": 0,
        "mean_distance_lost_m": 35.0,
    }


def test_a_restart_that_collides_is_kept_only_if_every_one_does() -> None:
    crashing_close = restart(13, score(-50.0, collisions=1))
    assert choose_restart([crashing_close, restart(14, score(80.0))]) == 1
    # every restart collides: the fewest collisions, then the least distance lost
    assert (
        choose_restart(
            [
                restart(13, score(10.0, collisions=2)),
                restart(14, score(90.0, collisions=1)),
                restart(15, score(70.0, collisions=1)),
            ]
        )
        == 2
    )


def test_a_restart_its_driver_took_over_loses_to_one_that_drove_on_its_own() -> None:
    """The scores had no hand-back until 2026-12-05: a restart that closed on its leader
    where the agent hands the car back to its driver kept the least distance lost and won."""
    needing_the_driver = restart(13, score(5.0, takeovers=2))
    assert choose_restart([needing_the_driver, restart(14, score(80.0))]) == 1
    # a collision still weighs more than any takeover
    assert choose_restart([restart(13, score(5.0, collisions=1)), needing_the_driver]) == 1


def test_ties_keep_the_first_seed() -> None:
    assert choose_restart([restart(13, score(25.0)), restart(14, score(25.0))]) == 0


def test_restarts_that_cannot_be_compared_are_refused() -> None:
    with pytest.raises(RestartChoiceError, match="no restart"):
        choose_restart([])
    with pytest.raises(RestartChoiceError, match="seed 14 has no scored drive"):
        choose_restart([restart(13, score(1.0)), restart(14)])
    with pytest.raises(RestartChoiceError, match="seed 13 has no distance lost"):
        choose_restart([restart(13, score(math.nan))])
    with pytest.raises(RestartChoiceError, match="seed 13 was scored with no hand-back"):
        choose_restart([restart(13, score(1.0, takeovers=None))])
