"""What the planner works on: the corridor's fine grid, the INRIX history, the fleet's observations.

Plain arrays in SI units, validated once here so the stages can trust their shapes. Positions are
x_m along the corridor (increasing in the direction of travel); lanes count from 1 at the left;
times are seconds since the Unix epoch.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from contract.units import MPS_PER_MPH

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

# INRIX readings outside 0-100 mph are not speeds of traffic (the sanity range).
MAX_INRIX_SPEED_MPS = 100 * MPS_PER_MPH


def _floats(values: ArrayLike) -> FloatArray:
    return np.asarray(values, dtype=np.float64)


@dataclass(frozen=True)
class CorridorGrid:
    """The fine sub-segments (paper: dim_i24_segment) of one corridor and its legal speed range."""

    corridor_id: str
    lanes: int
    start_x_m: FloatArray
    end_x_m: FloatArray
    segment_ids: IntArray
    speed_limit_mps: float
    min_target_speed_mps: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "start_x_m", _floats(self.start_x_m))
        object.__setattr__(self, "end_x_m", _floats(self.end_x_m))
        object.__setattr__(self, "segment_ids", np.asarray(self.segment_ids, dtype=np.int64))
        n = len(self.start_x_m)
        if n == 0:
            raise ValueError(f"corridor {self.corridor_id}: no sub-segments")
        if len(self.end_x_m) != n or len(self.segment_ids) != n:
            raise ValueError(f"corridor {self.corridor_id}: sub-segment arrays differ in length")
        if not 1 <= self.lanes <= 12:
            raise ValueError(f"corridor {self.corridor_id}: lanes must be 1-12, got {self.lanes}")
        if np.any(self.end_x_m <= self.start_x_m):
            raise ValueError(f"corridor {self.corridor_id}: a sub-segment ends before it starts")
        if np.any(self.start_x_m[1:] < self.end_x_m[:-1]):
            raise ValueError(f"corridor {self.corridor_id}: sub-segments overlap or are unsorted")
        if not 0 < self.min_target_speed_mps < self.speed_limit_mps:
            raise ValueError(
                f"corridor {self.corridor_id}: legal range must satisfy 0 < min target "
                f"({self.min_target_speed_mps}) < speed limit ({self.speed_limit_mps})"
            )

    @classmethod
    def from_rows(
        cls, corridor: Mapping[str, Any], sub_segments: Sequence[Mapping[str, Any]]
    ) -> CorridorGrid:
        """From dim_corridor and dim_i24_segment rows (or the seed file's, same columns)."""
        ordered = sorted(sub_segments, key=lambda row: float(row["start_x_m"]))
        return cls(
            corridor_id=str(corridor["corridor_id"]),
            lanes=int(corridor["lanes"]),
            start_x_m=np.array([float(row["start_x_m"]) for row in ordered]),
            end_x_m=np.array([float(row["end_x_m"]) for row in ordered]),
            segment_ids=np.array([int(row["i24_segment_id"]) for row in ordered]),
            speed_limit_mps=float(corridor["speed_limit_mps"]),
            min_target_speed_mps=float(corridor["min_target_speed_mps"]),
        )

    @property
    def cells(self) -> int:
        """Number of sub-segments."""
        return len(self.start_x_m)

    @property
    def center_x_m(self) -> FloatArray:
        """Centre of each sub-segment, where its TSE and target are evaluated."""
        centers: FloatArray = 0.5 * (self.start_x_m + self.end_x_m)
        return centers

    @property
    def length_m(self) -> FloatArray:
        """Length of each sub-segment."""
        lengths: FloatArray = self.end_x_m - self.start_x_m
        return lengths

    def cell_of(self, x_m: ArrayLike) -> IntArray:
        """Index of the sub-segment holding each position; -1 off the grid."""
        x = _floats(x_m)
        index = np.searchsorted(self.start_x_m, x, side="right") - 1
        inside = (index >= 0) & (x < self.end_x_m[np.clip(index, 0, self.cells - 1)])
        return np.where(inside, index, -1).astype(np.int64)


@dataclass(frozen=True)
class InrixHistory:
    """INRIX snapshots of one corridor: speed (m/s, NaN = no reading) per snapshot and segment.

    `is_reading` says which speeds INRIX reported in that snapshot; by default every finite one.
    A filled history (`planner.predict.usable_history`) has no NaN left, and its `is_reading`
    keeps apart what was read from what was carried forward or interpolated, so that a trend is
    fitted only on readings.
    """

    measured_at_s: FloatArray
    speed_mps: FloatArray
    segment_center_x_m: FloatArray
    is_reading: BoolArray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "measured_at_s", _floats(self.measured_at_s))
        object.__setattr__(self, "speed_mps", np.atleast_2d(_floats(self.speed_mps)))
        object.__setattr__(self, "segment_center_x_m", _floats(self.segment_center_x_m))
        if self.is_reading is None:
            object.__setattr__(self, "is_reading", np.isfinite(self.speed_mps))
        else:
            read = np.atleast_2d(np.asarray(self.is_reading, dtype=bool))
            if read.shape != self.speed_mps.shape:
                raise ValueError(
                    f"INRIX history: reading mask of shape {read.shape} for speeds of shape "
                    f"{self.speed_mps.shape}"
                )
            object.__setattr__(self, "is_reading", read)
        snapshots, segments = self.speed_mps.shape
        if snapshots != len(self.measured_at_s):
            raise ValueError(
                f"INRIX history: {snapshots} speed rows for {len(self.measured_at_s)} times"
            )
        if segments != len(self.segment_center_x_m):
            raise ValueError(
                f"INRIX history: {segments} speed columns for "
                f"{len(self.segment_center_x_m)} segments"
            )
        if np.any(np.diff(self.measured_at_s) <= 0):
            raise ValueError("INRIX history: snapshot times must increase strictly")
        if np.any(np.diff(self.segment_center_x_m) <= 0):
            raise ValueError("INRIX history: segment centres must increase along the corridor")

    @property
    def snapshots(self) -> int:
        """Number of snapshots."""
        return len(self.measured_at_s)

    def until(self, now_s: float) -> InrixHistory:
        """The snapshots measured at or before `now_s` (what a planner running then could see)."""
        keep = self.measured_at_s <= now_s
        return InrixHistory(
            self.measured_at_s[keep],
            self.speed_mps[keep],
            self.segment_center_x_m,
            self.readings[keep],
        )

    @property
    def readings(self) -> BoolArray:
        """`is_reading`, never None after construction."""
        assert self.is_reading is not None
        return self.is_reading


@dataclass(frozen=True)
class InrixCleaning:
    """Readings the planner refused, by reason (counted, logged, exported as metrics)."""

    not_a_number: int = 0
    out_of_range: int = 0

    @property
    def total(self) -> int:
        """All refused readings."""
        return self.not_a_number + self.out_of_range


def clean_inrix_speeds(speed_mps: ArrayLike) -> tuple[FloatArray, InrixCleaning]:
    """Blank out (NaN) readings that are not numbers or lie outside 0-100 mph, and count them."""
    speeds = _floats(speed_mps).copy()
    not_finite = ~np.isfinite(speeds)
    out_of_range = np.isfinite(speeds) & ((speeds < 0) | (speeds > MAX_INRIX_SPEED_MPS))
    speeds[not_finite | out_of_range] = np.nan
    return speeds, InrixCleaning(int(not_finite.sum()), int(out_of_range.sum()))


EngagedPings = Literal["all", "behind_leader"]


def traffic_pings(engaged: ArrayLike, lead_present: ArrayLike, rule: EngagedPings) -> BoolArray:
    """Which pings tell the traffic's speed, by the `engaged_pings` rule.

    A car whose controller is engaged follows the plan; with no leader in radar range nothing
    but the plan sets its speed, so its ping echoes the plan. Under "behind_leader" such pings
    drop; a car on its stock ACC or driven by hand, and an engaged car behind a leader, count.
    Under "all" every ping counts (the paper fuses every vehicle observation). The server's
    SQL (`planner.warehouse.PER_VEHICLE`) states the same rule, unknown flags read as false.
    """
    engaged_flags = np.asarray(engaged, dtype=bool)
    lead_flags = np.asarray(lead_present, dtype=bool)
    if engaged_flags.shape != lead_flags.shape:
        raise ValueError("pings: engaged and lead flags differ in length")
    if rule == "all":
        return np.ones(engaged_flags.shape, dtype=bool)
    return np.asarray(~engaged_flags | lead_flags, dtype=bool)


@dataclass(frozen=True)
class LaneObservations:
    """Fleet speeds per lane and sub-segment over the ping window (paper: vehicle observations).

    One row per (vehicle,) lane and sub-segment: the mean speed of the pings there and how many
    pings made it. Rows for the same cell (several vehicles) are pooled by ping count.
    """

    lane: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    cell: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    mean_speed_mps: FloatArray = field(default_factory=lambda: np.zeros(0))
    ping_count: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def __post_init__(self) -> None:
        object.__setattr__(self, "lane", np.asarray(self.lane, dtype=np.int64))
        object.__setattr__(self, "cell", np.asarray(self.cell, dtype=np.int64))
        object.__setattr__(self, "mean_speed_mps", _floats(self.mean_speed_mps))
        object.__setattr__(self, "ping_count", np.asarray(self.ping_count, dtype=np.int64))
        n = len(self.lane)
        if not len(self.cell) == len(self.mean_speed_mps) == len(self.ping_count) == n:
            raise ValueError("observations: lane, cell, speed and count arrays differ in length")
        if np.any(self.ping_count <= 0):
            raise ValueError("observations: every row needs at least one ping")
        if not np.all(np.isfinite(self.mean_speed_mps)) or np.any(self.mean_speed_mps < 0):
            raise ValueError("observations: speeds must be finite and not negative")

    def __len__(self) -> int:
        return len(self.lane)

    def pooled(self, grid: CorridorGrid) -> tuple[FloatArray, IntArray]:
        """Ping-weighted mean speed (NaN where unobserved) and ping count per (lane, cell)."""
        if np.any((self.lane < 1) | (self.lane > grid.lanes)):
            raise ValueError(f"observations: lanes must be 1-{grid.lanes} on {grid.corridor_id}")
        if np.any((self.cell < 0) | (self.cell >= grid.cells)):
            raise ValueError(f"observations: sub-segment index outside 0-{grid.cells - 1}")
        counts = np.zeros((grid.lanes, grid.cells), dtype=np.int64)
        weighted = np.zeros((grid.lanes, grid.cells))
        np.add.at(counts, (self.lane - 1, self.cell), self.ping_count)
        np.add.at(weighted, (self.lane - 1, self.cell), self.ping_count * self.mean_speed_mps)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(counts > 0, weighted / np.maximum(counts, 1), np.nan)
        return mean, counts

    @classmethod
    def from_pings(
        cls, grid: CorridorGrid, lane: ArrayLike, x_m: ArrayLike, speed_mps: ArrayLike
    ) -> LaneObservations:
        """Pool raw pings (lane, position, speed) per lane and sub-segment; off-grid pings drop."""
        lanes = np.asarray(lane, dtype=np.int64)
        cells = grid.cell_of(x_m)
        speeds = _floats(speed_mps)
        keep = (cells >= 0) & (lanes >= 1) & (lanes <= grid.lanes) & np.isfinite(speeds)
        key = (lanes[keep] - 1) * grid.cells + cells[keep]
        counts = np.bincount(key, minlength=grid.lanes * grid.cells)
        sums = np.bincount(key, weights=speeds[keep], minlength=grid.lanes * grid.cells)
        seen = np.nonzero(counts)[0]
        return cls(
            lane=seen // grid.cells + 1,
            cell=seen % grid.cells,
            mean_speed_mps=sums[seen] / counts[seen],
            ping_count=counts[seen],
        )
