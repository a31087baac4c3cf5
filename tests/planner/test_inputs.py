"""The planner's inputs refuse what they cannot use, with a message saying what was wrong."""

from __future__ import annotations

import numpy as np
import pytest

from planner.inputs import (
    MAX_INRIX_SPEED_MPS,
    CorridorGrid,
    InrixHistory,
    LaneObservations,
    clean_inrix_speeds,
    traffic_pings,
)
from planner.registry import Registry, UnknownVariant
from tests.planner.grids import uniform_grid


def test_grid_refuses_overlapping_sub_segments() -> None:
    with pytest.raises(ValueError, match="overlap"):
        CorridorGrid("X", 2, [0, 50], [100, 150], [1, 2], 30.0, 9.0)


def test_grid_refuses_an_empty_legal_range() -> None:
    with pytest.raises(ValueError, match="legal range"):
        CorridorGrid("X", 2, [0], [100], [1], 9.0, 30.0)


def test_cell_of_maps_positions_and_marks_off_grid() -> None:
    grid = uniform_grid(3)
    assert grid.cell_of([-1.0, 0.0, 99.9, 100.0, 299.9, 300.0]).tolist() == [-1, 0, 0, 1, 2, -1]


def test_inrix_readings_out_of_range_or_not_numbers_are_blanked_and_counted() -> None:
    speeds, cleaning = clean_inrix_speeds(
        [[20.0, np.nan, -1.0], [MAX_INRIX_SPEED_MPS + 0.1, np.inf, 0.0]]
    )
    assert np.isnan(speeds).sum() == 4
    assert speeds[0, 0] == 20.0
    assert speeds[1, 2] == 0.0
    assert (cleaning.not_a_number, cleaning.out_of_range, cleaning.total) == (2, 2, 4)


def test_inrix_history_refuses_unsorted_snapshots() -> None:
    with pytest.raises(ValueError, match="increase"):
        InrixHistory([60.0, 0.0], [[30.0], [30.0]], [500.0])


def test_observations_of_one_cell_pool_by_ping_count() -> None:
    grid = uniform_grid(2, lanes=2)
    observations = LaneObservations(
        lane=[1, 1, 2], cell=[0, 0, 1], mean_speed_mps=[20.0, 24.0, 10.0], ping_count=[10, 30, 5]
    )
    mean, counts = observations.pooled(grid)
    assert mean[0, 0] == pytest.approx((10 * 20 + 30 * 24) / 40)
    assert counts.tolist() == [[40, 0], [0, 5]]
    assert np.isnan(mean[0, 1])
    assert np.isnan(mean[1, 0])


def test_observations_in_a_lane_the_corridor_lacks_are_refused() -> None:
    observations = LaneObservations(lane=[3], cell=[0], mean_speed_mps=[20.0], ping_count=[1])
    with pytest.raises(ValueError, match="lanes must be 1-2"):
        observations.pooled(uniform_grid(2, lanes=2))


def test_pings_off_the_grid_do_not_become_observations() -> None:
    grid = uniform_grid(2, lanes=2)
    observations = LaneObservations.from_pings(
        grid, lane=[1, 1, 2, 5], x_m=[10.0, 20.0, 500.0, 10.0], speed_mps=[20.0, 22.0, 9.0, 9.0]
    )
    assert observations.lane.tolist() == [1]
    assert observations.mean_speed_mps.tolist() == [21.0]
    assert observations.ping_count.tolist() == [2]


def test_an_unknown_variant_names_the_known_ones() -> None:
    registry: Registry[int] = Registry("kernel")
    registry.register("uniform", 1)
    with pytest.raises(UnknownVariant, match=r"unknown kernel 'box' \(known: uniform\)"):
        registry.get("box")


def test_the_engaged_pings_rule_keeps_what_tells_the_traffics_speed() -> None:
    engaged = [False, False, True, True]
    lead = [False, True, False, True]
    assert traffic_pings(engaged, lead, "all").tolist() == [True, True, True, True]
    # only an engaged car with nothing in radar range drives the plan's own speed
    assert traffic_pings(engaged, lead, "behind_leader").tolist() == [True, True, False, True]
    with pytest.raises(ValueError, match="differ in length"):
        traffic_pings([True], [True, False], "all")
