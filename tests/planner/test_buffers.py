"""Step 5: a buffer holding the queue's vehicles at its speed, reached by a gentle ramp."""

from __future__ import annotations

import math

import numpy as np
import pytest

from contract.idm import I24_IDM, equilibrium_density_per_m, equilibrium_gap_m
from planner.buffers import DESIGNERS, BufferDesign, apply_buffers
from planner.params import PlannerParams
from tests.planner.grids import uniform_grid

GRID = uniform_grid(150)
# Free flow at 30 m/s with a 1 km queue at 8 m/s over 9-10 km (cells 90-99).
TSE = np.where((GRID.center_x_m > 9000) & (GRID.center_x_m < 10000), 8.0, 30.0)[None, :]
SMOOTHED = np.full((1, 150), 30.0)
HEAD = np.zeros((1, 150), dtype=bool)
HEAD[0, 99] = True
PARAMS = PlannerParams(buffer_speed_margin_mps=2.0, ramp_decel_mps2=0.1, floor_fraction=0.8)


def design(tse: np.ndarray = TSE, standing: np.ndarray = HEAD) -> BufferDesign:
    return DESIGNERS.get("queue_storage")(tse, SMOOTHED, standing, GRID, PARAMS)


def test_idm_equilibrium_density_worked_by_hand() -> None:
    # s(8) = (2 + 1.24 x 8) / sqrt(1 - (8/35)^4) = 11.92 / 0.998634 = 11.9363 m
    assert equilibrium_gap_m(I24_IDM, 8.0) == pytest.approx(11.9363, abs=1e-4)
    assert equilibrium_density_per_m(I24_IDM, 8.0) == pytest.approx(1 / 15.9363, rel=1e-5)
    assert equilibrium_density_per_m(I24_IDM, 35.0) == 0.0  # at v0 the gap is unbounded


def test_buffer_length_and_speed_worked_by_hand() -> None:
    (buffer,) = design().buffers
    # Queue: 1000 m x k(8) = 1000 / 15.9363 = 62.750 vehicles. Buffer speed 8 + 2 = 10 m/s,
    # k(10) = 1 / (14.4 / sqrt(1 - (10/35)^4) + 4) = 1 / 18.4482, so L = 62.750 x 18.4482
    # = 1157.6 m, ending where the queue starts (9000 m).
    assert buffer.queue_vehicles == pytest.approx(62.750, abs=1e-3)
    assert buffer.target_speed_mps == 10.0
    vehicles = 1000 * float(equilibrium_density_per_m(I24_IDM, 8.0))
    plateau_start = 9000 - vehicles / float(equilibrium_density_per_m(I24_IDM, 10.0))
    assert plateau_start == pytest.approx(9000 - 1157.6, abs=0.1)
    ceiling = design().ceiling_mps[0]
    assert ceiling[78:90].tolist() == [10.0] * 12  # centres 7850 ... 8950
    # Upstream the ceiling ramps at -0.1 m/s^2: v = sqrt(10^2 + 2 x 0.1 x distance).
    assert ceiling[77] == pytest.approx(math.sqrt(100 + 0.2 * (plateau_start - 7750)))
    # It reaches free-flow speed 4 km before the plateau: the buffer starts at 3800 m.
    assert (buffer.lane, buffer.start_x_m, buffer.end_x_m) == (1, 3800.0, 9000.0)
    assert np.all(np.isinf(ceiling[90:]))  # the queue and beyond: the smoothed TSE


def test_a_queue_of_mixed_speeds_is_buffered_at_its_slowest_plus_the_margin() -> None:
    # The same queue, its first half at 6 m/s and its second at 10: the buffer holds the
    # slowest, 6 + 2 = 8 m/s (their mean would be 10), and stores what both halves hold.
    mixed = TSE.copy()
    mixed[0, 90:95] = 6.0
    mixed[0, 95:100] = 10.0
    (buffer,) = design(mixed).buffers
    assert buffer.target_speed_mps == 8.0
    held = 500 * float(
        equilibrium_density_per_m(I24_IDM, 6.0) + equilibrium_density_per_m(I24_IDM, 10.0)
    )
    assert buffer.queue_vehicles == pytest.approx(held)


def test_the_floor_keeps_targets_near_the_smoothed_speed() -> None:
    target, is_buffer = apply_buffers(SMOOTHED, design(), PARAMS)
    assert np.argwhere(is_buffer[0]).ravel().tolist() == list(range(38, 90))
    assert target[0, 85] == pytest.approx(24.0)  # max(10, 0.8 x 30)
    assert target[0, 95] == 30.0
    assert target[0, 10] == 30.0
    unfloored = PARAMS.model_copy(update={"floor_fraction": 0.0})
    target, _ = apply_buffers(SMOOTHED, design(), unfloored)
    assert target[0, 85] == 10.0


def test_no_standing_bottleneck_no_buffer() -> None:
    empty = design(standing=np.zeros_like(HEAD))
    assert empty.buffers == ()
    assert np.all(np.isinf(empty.ceiling_mps))


def test_a_head_upstream_of_its_queue_finds_it_within_the_window() -> None:
    early = np.zeros_like(HEAD)
    early[0, 85] = True  # 500 m before the queue: the forward window sees it
    assert design(standing=early).buffers == design().buffers
    far = np.zeros_like(HEAD)
    far[0, 60] = True  # 3 km before: no queue within the 1.5 km window
    assert design(standing=far).buffers == ()
