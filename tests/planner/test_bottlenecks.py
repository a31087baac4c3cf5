"""Step 4: bottleneck heads on the smoothed lane TSE, standing only after enough cycles."""

from __future__ import annotations

import numpy as np

from contract.units import MPS_PER_MPH
from planner.bottlenecks import FINDERS, standing_bottlenecks
from planner.params import PlannerParams
from tests.planner.grids import uniform_grid

GRID = uniform_grid(7, lanes=2)
PARAMS = PlannerParams(rise_distance_m=100.0, match_distance_m=100.0)


def test_the_head_is_the_last_slow_cell_before_the_rise() -> None:
    smoothed = np.array([[30, 30, 10, 10, 10, 30, 30], [30] * 7], dtype=float)
    heads = FINDERS.get("speed_rise")(smoothed, GRID, PARAMS)
    assert np.argwhere(heads).tolist() == [[0, 4]]


def test_a_rise_of_less_than_four_mph_is_no_head() -> None:
    slow = 50 * MPS_PER_MPH
    smoothed = np.array(
        [[slow, slow, slow + 3.9 * MPS_PER_MPH, slow + 3.9 * MPS_PER_MPH, 30, 30, 30]] * 2
    )
    heads = FINDERS.get("speed_rise")(smoothed, GRID, PARAMS)
    # 50 -> 53.9 mph is not a rise > 4 mph; 53.9 mph -> 30 m/s (67 mph) is.
    assert np.argwhere(heads[0]).ravel().tolist() == [3]


def test_a_rise_above_sixty_mph_is_no_bottleneck() -> None:
    smoothed = np.array([[27.5, 27.5, 33.0, 33.0, 33.0, 33.0, 33.0]] * 2)  # 61.5 -> 73.8 mph
    assert not FINDERS.get("speed_rise")(smoothed, GRID, PARAMS).any()


def test_the_rise_may_come_within_the_rise_distance() -> None:
    smoothed = np.array([[10, 10, 12, 14, 16, 30, 30]] * 2, dtype=float)
    near = FINDERS.get("speed_rise")(smoothed, GRID, PARAMS)
    far = FINDERS.get("speed_rise")(
        smoothed, GRID, PARAMS.model_copy(update={"rise_distance_m": 300.0})
    )
    # Cell to cell only the last step (16 -> 30) rises > 4 mph; within 300 m each cell sees it.
    assert np.argwhere(near[0]).ravel().tolist() == [4]
    assert np.argwhere(far[0]).ravel().tolist() == [4]
    assert near.sum() == far.sum() == 2


def test_standing_only_after_four_of_the_last_five_cycles() -> None:
    head = np.zeros((2, 7), dtype=bool)
    head[1, 4] = True
    nothing = np.zeros_like(head)
    history: list[np.ndarray] = []
    standing_by_cycle = []
    for current in [head, head, nothing, head, head, head]:
        standing = standing_bottlenecks(current, history, GRID, PARAMS)
        standing_by_cycle.append(bool(standing[1, 4]))
        history.insert(0, current)
    # Seen in cycles 1, 2, 4: not yet; cycle 5 is the fourth sighting in the last five.
    assert standing_by_cycle == [False, False, False, False, True, True]


def test_a_head_that_moves_beyond_the_match_distance_is_a_moving_wave() -> None:
    history = []
    for cell in (6, 5, 4, 3):  # one cell (100 m) upstream per cycle: a wave at 6 km/h
        current = np.zeros((2, 7), dtype=bool)
        current[0, cell] = True
        standing = standing_bottlenecks(current, history, GRID, PARAMS)
        history.insert(0, current)
    # Within 100 m of cell 3 only cells 2-4 count: cycles with heads at 4 and 3.
    assert not standing.any()
    wide = PARAMS.model_copy(update={"match_distance_m": 300.0})
    assert standing_bottlenecks(history[0], history[1:], GRID, wide)[0, 3]


def test_a_head_in_another_lane_does_not_count() -> None:
    lane1 = np.zeros((2, 7), dtype=bool)
    lane1[0, 4] = True
    lane2 = np.zeros((2, 7), dtype=bool)
    lane2[1, 4] = True
    standing = standing_bottlenecks(lane1, [lane2, lane2, lane2, lane2], GRID, PARAMS)
    assert not standing.any()
