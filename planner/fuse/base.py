"""Step 2 interface: fuse the predicted INRIX profile with the fleet's lane observations.

INRIX is one speed across all lanes; the fleet's pings of the last window are lane-specific. A
fuser returns the lane-level TSE: one speed per lane and sub-segment, everywhere.
"""

from __future__ import annotations

from typing import Protocol

from planner.inputs import CorridorGrid, FloatArray, LaneObservations
from planner.params import PlannerParams


class Fuser(Protocol):
    """A fusion variant (registered in planner.fuse.FUSERS)."""

    def __call__(
        self,
        prior_mps: FloatArray,
        observations: LaneObservations,
        grid: CorridorGrid,
        params: PlannerParams,
    ) -> FloatArray:
        """Lane-level TSE, shape (lanes, sub-segments), from the prior (sub-segments,)."""
        ...
