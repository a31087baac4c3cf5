"""The MOTION frame onto the corridor: worked by hand from the documented transform."""

from __future__ import annotations

import numpy as np
import pytest

from contract.units import METRES_PER_FOOT
from sim.motion.frame import EASTBOUND, MotionFrame


def test_default_tie_point_is_milepost_66_at_the_reference_lines_origin() -> None:
    frame = MotionFrame()
    assert frame.x_m(66.0 * 5280.0) == pytest.approx(717.1659)


def test_westbound_travel_towards_smaller_mileposts_is_increasing_x_m() -> None:
    frame = MotionFrame()
    # One mile further west (milepost 65) is 1609.344 m further along the corridor.
    assert frame.x_m(65.0 * 5280.0) == pytest.approx(717.1659 + 1609.344)
    # The real record starts at 314836.97 ft: (348480 - 314836.97) * 0.3048 + 717.1659
    # = 33643.03 * 0.3048 + 717.17 = 10254.40 + 717.17.
    assert frame.x_m(314836.96589700034) == pytest.approx(10971.56, abs=0.01)


def test_eastbound_frame_runs_the_other_way_from_its_tie_point() -> None:
    frame = MotionFrame(direction=EASTBOUND, anchor_x_ft=1000.0, anchor_x_m=0.0)
    assert frame.x_m([1000.0, 1100.0]) == pytest.approx([0.0, 100 * METRES_PER_FOOT])


@pytest.mark.parametrize("direction", [-1, 1])
def test_x_ft_inverts_x_m(direction: int) -> None:
    frame = MotionFrame(direction=direction)
    x_m = np.array([0.0, 5000.0, 14585.72])
    assert frame.x_m(frame.x_ft(x_m)) == pytest.approx(x_m)


def test_lanes_count_from_the_median_in_12_ft_steps_after_the_inside_shoulder() -> None:
    frame = MotionFrame()
    # |y| - 12 ft, in 12 ft lanes: 13 -> 1, 35.9 -> 2, 36 -> 3, 65 -> 5 (beyond the 4 lanes:
    # kept as computed), inside the median -> 0; the sign (carriageway) does not matter.
    assert frame.lane([13.0, 35.9, 36.0, 65.15, 5.0, -30.0]).tolist() == [1, 2, 3, 5, 0, 2]


def test_y_ft_is_the_lane_centre_on_the_directions_side() -> None:
    assert MotionFrame().y_ft([1, 4]) == pytest.approx([18.0, 54.0])
    assert MotionFrame(direction=EASTBOUND).y_ft(1) == pytest.approx(-18.0)
    assert MotionFrame().lane(MotionFrame().y_ft([1, 2, 3, 4])).tolist() == [1, 2, 3, 4]


def test_a_frame_without_a_direction_is_refused() -> None:
    with pytest.raises(ValueError, match="direction must be -1"):
        MotionFrame(direction=0)
