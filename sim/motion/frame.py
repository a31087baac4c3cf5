"""The I-24 MOTION roadway frame mapped onto the corridor's `x_m` and lanes.

I-24 MOTION gives positions in feet in its own roadway frame: `x_position` along the road and
`y_position` across it. Its x is the I-24 milepost in feet (x / 5280 = milepost; the real record in
../shared/data/i24motion lies at 59.5-59.6 mi, inside the testbed's mileposts 58.7-62.7), and
mileposts grow eastbound, so a westbound vehicle (`direction` = -1) drives towards smaller x. The
corridor's `x_m` grows in the direction of travel (interfaces.md), so for the westbound corridor

    x_m = anchor_x_m + (anchor_x_ft - x_ft) * 0.3048                           (westbound)
    x_m = anchor_x_m + (x_ft - anchor_x_ft) * 0.3048                           (eastbound)

with one tie point (anchor_x_ft, anchor_x_m). The default tie: milepost 66.0 (I-24 exit 66,
the interchange at position 0 of the reference line ../shared/data/geo/i24_geo.json), which is
corridor x_m = 717.17 m (the seed corridor starts 717.17 m before that point,
`reference_line_origin_m`). The tie is an estimate good to a few hundred metres; an analyst with
a surveyed tie passes their own `MotionFrame`.

Lanes: `y_position` is the lateral offset in feet from the road's centre line (its sign says
the carriageway). Lanes are numbered from 1 at the median side (interfaces.md), each
`lane_width_ft` wide, beginning `median_offset_ft` from the centre line (the inside shoulder):

    lane = floor((|y_ft| - median_offset_ft) / lane_width_ft) + 1

A lane number above the corridor's lane count (an auxiliary lane or the outside shoulder) is kept
as computed; a y inside the median gives lane 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from contract.units import FEET_PER_MILE, METRES_PER_FOOT

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int16]

# Westbound in MOTION documents (eastbound is +1).
WESTBOUND = -1
EASTBOUND = 1
# Default tie point: milepost 66.0 at reference-line position 0, which the seed corridor places
# at x_m = 717.17 m (its reference_line_origin_m is -717.1659 m).
DEFAULT_ANCHOR_X_FT = 66.0 * FEET_PER_MILE
DEFAULT_ANCHOR_X_M = 717.1659
# A US interstate lane is 12 ft wide; the inside shoulder is taken as one lane width.
LANE_WIDTH_FT = 12.0
MEDIAN_OFFSET_FT = 12.0


@dataclass(frozen=True, slots=True)
class MotionFrame:
    """The affine map from MOTION's (x_position, y_position) in feet to (x_m, lane)."""

    direction: int = WESTBOUND
    anchor_x_ft: float = DEFAULT_ANCHOR_X_FT
    anchor_x_m: float = DEFAULT_ANCHOR_X_M
    lane_width_ft: float = LANE_WIDTH_FT
    median_offset_ft: float = MEDIAN_OFFSET_FT

    def __post_init__(self) -> None:
        if self.direction not in (WESTBOUND, EASTBOUND):
            raise ValueError(
                f"direction must be -1 (westbound) or 1 (eastbound), not {self.direction}"
            )
        if not self.lane_width_ft > 0:
            raise ValueError(f"lane_width_ft must be positive, not {self.lane_width_ft}")

    def x_m(self, x_ft: ArrayLike) -> FloatArray:
        """Corridor position of MOTION x positions (metres, increasing with travel)."""
        x = np.asarray(x_ft, dtype=np.float64)
        result: FloatArray = self.anchor_x_m + self.direction * (x - self.anchor_x_ft) * (
            METRES_PER_FOOT
        )
        return result

    def x_ft(self, x_m: ArrayLike) -> FloatArray:
        """MOTION x position (feet) of corridor positions: the inverse of `x_m`."""
        x = np.asarray(x_m, dtype=np.float64)
        result: FloatArray = self.anchor_x_ft + self.direction * (x - self.anchor_x_m) / (
            METRES_PER_FOOT
        )
        return result

    def lane(self, y_ft: ArrayLike) -> IntArray:
        """Lane number (1 at the median) of MOTION y positions; 0 inside the median."""
        offset = np.abs(np.asarray(y_ft, dtype=np.float64)) - self.median_offset_ft
        lanes = np.floor(offset / self.lane_width_ft) + 1.0
        result: IntArray = np.maximum(lanes, 0.0).astype(np.int16)
        return result

    def y_ft(self, lane: ArrayLike) -> FloatArray:
        """MOTION y position (feet) of a lane's centre, on this direction's side of the road."""
        centre = self.median_offset_ft + (np.asarray(lane, dtype=np.float64) - 0.5) * (
            self.lane_width_ft
        )
        result: FloatArray = -self.direction * centre
        return result
