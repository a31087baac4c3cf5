"""Step 2: the fleet's lane observations take precedence over INRIX (paper, TSE Enhancement)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.fuse import FUSERS
from planner.inputs import LaneObservations
from planner.params import PlannerParams
from tests.planner.grids import uniform_grid

PRIOR = np.full(5, 30.0)


def observed(lane: int, cell: int, *pairs: tuple[float, int]) -> LaneObservations:
    """Observations of one cell: (mean speed, ping count) per vehicle."""
    return LaneObservations(
        lane=[lane] * len(pairs),
        cell=[cell] * len(pairs),
        mean_speed_mps=[speed for speed, _ in pairs],
        ping_count=[count for _, count in pairs],
    )


def test_without_observations_every_lane_is_the_prior() -> None:
    tse = FUSERS.get("precedence")(
        PRIOR, LaneObservations(), uniform_grid(5, lanes=3), PlannerParams()
    )
    assert tse.shape == (3, 5)
    assert np.all(tse == 30.0)


def test_a_driven_cell_takes_the_ping_weighted_fleet_speed() -> None:
    grid = uniform_grid(5, lanes=2)
    params = PlannerParams(correction_length_m=0.0, other_lane_weight=0.5)
    tse = FUSERS.get("precedence")(PRIOR, observed(1, 2, (20.0, 10), (24.0, 30)), grid, params)
    assert tse[0, 2] == pytest.approx(23.0)  # (10 x 20 + 30 x 24) / 40
    # The other lane at the same cell: prior + w r / (1 + w), r = -7, w = 0.5.
    assert tse[1, 2] == pytest.approx(30.0 - 3.5 / 1.5)
    # With no correction length, other cells keep the prior.
    assert tse[0, [0, 1, 3, 4]].tolist() == [30.0] * 4


def test_an_observation_corrects_its_neighbours_fading_with_distance() -> None:
    grid = uniform_grid(5)
    params = PlannerParams(correction_length_m=100.0)
    tse = FUSERS.get("precedence")(PRIOR, observed(1, 2, (23.0, 60)), grid, params)
    near = math.exp(-1.0)  # 100 m away
    far = math.exp(-2.0)  # 200 m away
    assert tse[0, 1] == pytest.approx(30.0 - 7.0 * near / (1 + near))
    assert tse[0, 3] == pytest.approx(30.0 - 7.0 * near / (1 + near))
    assert tse[0, 0] == pytest.approx(30.0 - 7.0 * far / (1 + far))
    assert tse[0, 2] == 23.0


def test_a_stopped_car_next_to_a_slow_prior_never_makes_traffic_reverse() -> None:
    # the car stands (0 m/s) where INRIX says 25: r = -25, which at 100 m, next to a prior of
    # 2 m/s, would give 2 - 25 e^-1 / (1 + e^-1) = -4.7 m/s
    grid = uniform_grid(5)
    prior = np.array([2.0, 2.0, 25.0, 30.0, 30.0])
    params = PlannerParams(correction_length_m=100.0)
    tse = FUSERS.get("precedence")(prior, observed(1, 2, (0.0, 60)), grid, params)
    assert tse[0, 1] == 0.0
    assert tse[0, 2] == 0.0
    near = math.exp(-1.0)
    assert tse[0, 3] == pytest.approx(30.0 - 25.0 * near / (1 + near))
    assert np.all(tse >= 0.0)


def test_observations_on_both_sides_and_in_another_lane_add_their_weights() -> None:
    """Every other test has one observed cell, where the weights' sum and their largest are
    the same: two residuals of -10 at 100 m on either side, and one of -6 in the other lane."""
    grid = uniform_grid(5, lanes=2)
    params = PlannerParams(correction_length_m=100.0, other_lane_weight=0.5)
    both_sides = LaneObservations(
        lane=[1, 1, 2], cell=[1, 3, 2], mean_speed_mps=[20.0, 20.0, 24.0], ping_count=[10, 10, 10]
    )
    tse = FUSERS.get("precedence")(PRIOR, both_sides, grid, params)
    near = math.exp(-1.0)
    # lane 1, cell 2: w = e^-1, e^-1 (own lane), 0.5 (the other lane's, 0 m away)
    own = 2 * near * -10.0 + 0.5 * -6.0
    assert tse[0, 2] == pytest.approx(30.0 + own / (1 + 2 * near + 0.5))
    # lane 2, cell 1: its own observation 100 m away (e^-1), lane 1's at 0 m (0.5) and 200 m
    other = near * -6.0 + 0.5 * -10.0 + 0.5 * math.exp(-2.0) * -10.0
    assert tse[1, 1] == pytest.approx(30.0 + other / (1 + near + 0.5 + 0.5 * math.exp(-2.0)))
