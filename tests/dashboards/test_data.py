"""Pure helpers behind the plan page: buffer regions and sampling plans onto a time-space grid."""

from __future__ import annotations

import numpy as np

from dashboards.data import LaneProfile, TimeSpace, sample_plans


def test_adjacent_buffer_segments_merge_into_one_region() -> None:
    profile = LaneProfile(
        lane=1,
        start_postmile=[0.0, 0.1, 0.2, 0.3, 0.4],
        end_postmile=[0.1, 0.2, 0.3, 0.4, 0.5],
        target_mps=[30.0, 20.0, 20.0, 30.0, 20.0],
        tse_mps=[None] * 5,
        is_buffer=[False, True, True, False, True],
    )
    assert profile.buffers() == [(0.1, 0.3), (0.4, 0.5)]


def test_each_cell_takes_the_plan_in_force_at_its_time_and_the_segment_at_its_postmile() -> None:
    # Two plans of two segments ([0, 1) and [1, 3) mi): the first from t = 100 s until 160 s,
    # the second from 160 s until 400 s.
    field = TimeSpace(
        published_at=np.array([100.0, 160.0]),
        valid_until=np.array([280.0, 400.0]),
        segment_edges_postmile=np.array([0.0, 1.0, 3.0]),
        target_mps=np.array([[10.0, 20.0], [30.0, 40.0]]),
        tse_mps=np.full((2, 2), np.nan),
    )
    times = np.array([50.0, 120.0, 200.0, 500.0])
    postmiles = np.array([0.5, 2.0, 5.0])

    grid = sample_plans(field, field.target_mps, times, postmiles)

    assert grid.shape == (3, 4)  # rows = postmile, columns = time
    np.testing.assert_array_equal(grid[:, 1], [10.0, 20.0, np.nan])
    np.testing.assert_array_equal(grid[:, 2], [30.0, 40.0, np.nan])
    assert np.isnan(grid[:, 0]).all()  # before the first plan
    assert np.isnan(grid[:, 3]).all()  # after the last one expired
