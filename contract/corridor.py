"""Corridor geometry: map a GPS fix to its position x_m along a corridor, and back.

Shared by the car (geofence, plan lookup) and the server (ping map-matching, observations,
simulated fleets), so it lives in the contract both import; it needs nothing but numpy.

The corridor is the polyline through its sub-segments' end points (<= 100 m apart on the seed
corridor, so the chord error on highway curves is a few metres). Positions are projected in a
local equirectangular plane, which is exact to well under a metre over a few tens of km.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

EARTH_RADIUS_M = 6_371_008.8
# A fix farther than this from the reference line is off the corridor. The seed reference line
# (../shared/data/geo) runs 20-50 m beside the westbound lanes, so 100 m keeps every real I-24
# drive on the corridor while an exit ramp or a parallel road a few hundred metres away is off.
ON_CORRIDOR_MAX_OFFSET_M = 100.0
# A fix whose GPS heading differs more than this from the corridor's direction of travel is on
# the opposite carriageway (or turning off), not on this corridor.
MAX_HEADING_DIFFERENCE_DEG = 90.0
# GPS headings below this speed are noise (a stopped car's heading wanders).
MIN_SPEED_FOR_HEADING_MPS = 2.0
# Points projected per block: bounds the (points x segments) work array to a few MB.
_BLOCK_ELEMENTS = 2_000_000
# Grid cell edge of the candidate index (a few sub-segments per cell), and the most
# (cells x sub-segments) it may weigh at build time; longer corridors get coarser cells.
_CELL_M = 250.0
_INDEX_ELEMENTS = 4_000_000

FloatArray = NDArray[np.float64]


def trusted_heading(heading_deg: ArrayLike, speed_mps: ArrayLike) -> FloatArray:
    """Headings worth checking against the corridor: NaN where unknown or the car too slow."""
    heading = np.asarray(heading_deg, dtype=np.float64)
    speed = np.asarray(speed_mps, dtype=np.float64)
    trusted: FloatArray = np.where(speed >= MIN_SPEED_FOR_HEADING_MPS, heading, np.nan)
    return trusted


@dataclass(frozen=True)
class Located:
    """Where fixes fall on the corridor: position, distance from the line, on or off it."""

    x_m: FloatArray
    offset_m: FloatArray
    on_corridor: NDArray[np.bool_]


class CorridorGeometry:
    """A corridor's reference polyline with x_m at each vertex (increasing along travel)."""

    def __init__(
        self,
        corridor_id: str,
        x_m: ArrayLike,
        lat: ArrayLike,
        lon: ArrayLike,
        *,
        lanes: int,
        max_offset_m: float = ON_CORRIDOR_MAX_OFFSET_M,
    ) -> None:
        self.corridor_id = corridor_id
        self.lanes = lanes
        self.max_offset_m = max_offset_m
        self.x_m = np.asarray(x_m, dtype=np.float64)
        self.lat = np.asarray(lat, dtype=np.float64)
        self.lon = np.asarray(lon, dtype=np.float64)
        if not (len(self.x_m) == len(self.lat) == len(self.lon) >= 2):
            raise ValueError("a corridor needs at least two vertices with x_m, lat and lon")
        if np.any(np.diff(self.x_m) <= 0):
            raise ValueError("corridor x_m must increase strictly along the vertices")
        self._lat0 = float(self.lat.mean())
        self._lon0 = float(self.lon.mean())
        self._cos_lat0 = math.cos(math.radians(self._lat0))
        self._points = self._to_plane(self.lat, self.lon)
        self._starts = self._points[:-1]
        self._steps = np.diff(self._points, axis=0)
        self._step_len2 = np.einsum("ij,ij->i", self._steps, self._steps)
        self._build_index()

    @classmethod
    def from_segments(
        cls, corridor_id: str, lanes: int, segments: Sequence[Mapping[str, Any]]
    ) -> CorridorGeometry:
        """Build from ordered sub-segments with start/end x_m, lat and lon (ValueError for
        none: a corridor whose sub-segments are not loaded yet has no geometry)."""
        if not segments:
            raise ValueError(f"corridor {corridor_id} has no sub-segments")
        ordered = sorted(segments, key=lambda segment: float(segment["start_x_m"]))
        x_m = [float(s["start_x_m"]) for s in ordered] + [float(ordered[-1]["end_x_m"])]
        lat = [float(s["start_lat"]) for s in ordered] + [float(ordered[-1]["end_lat"])]
        lon = [float(s["start_lon"]) for s in ordered] + [float(ordered[-1]["end_lon"])]
        return cls(corridor_id, x_m, lat, lon, lanes=lanes)

    @property
    def length_m(self) -> float:
        """Position of the corridor's end."""
        return float(self.x_m[-1])

    def _to_plane(self, lat: FloatArray, lon: FloatArray) -> FloatArray:
        east = np.radians(lon - self._lon0) * EARTH_RADIUS_M * self._cos_lat0
        north = np.radians(lat - self._lat0) * EARTH_RADIUS_M
        return np.column_stack([east, north])

    def locate(
        self, lat: ArrayLike, lon: ArrayLike, heading_deg: ArrayLike | None = None
    ) -> Located:
        """Project fixes onto the corridor (vectorised over fixes).

        With `heading_deg` (NaN where unknown, e.g. a car too slow for GPS to tell), a fix
        heading against the corridor's direction of travel is off it: the opposite carriageway
        runs within `max_offset_m` of the reference line, and its traffic must not feed this
        corridor's estimate nor let a car engage.

        Each fix is first tried against the few sub-segments listed for its grid cell (see
        `_build_index`); a fix not within `max_offset_m` of one of them (off the corridor, or
        outside the grid) is projected onto every sub-segment. Both give the same nearest
        sub-segment: a sub-segment within `max_offset_m` of a fix is always listed in its cell.
        """
        lat_a = np.atleast_1d(np.asarray(lat, dtype=np.float64))
        lon_a = np.atleast_1d(np.asarray(lon, dtype=np.float64))
        points = self._to_plane(lat_a, lon_a)
        x_out = np.empty(len(points))
        offset_out = np.empty(len(points))
        resolved = self._locate_by_cell(points, x_out, offset_out)
        rest = np.flatnonzero(~resolved)
        block = max(1, _BLOCK_ELEMENTS // len(self._starts))
        for first in range(0, len(rest), block):
            which = rest[first : first + block]
            chunk = points[which]
            relative = chunk[:, None, :] - self._starts[None, :, :]
            fraction = np.einsum("pij,ij->pi", relative, self._steps) / self._step_len2
            fraction = np.clip(fraction, 0.0, 1.0)
            nearest = self._starts[None] + fraction[..., None] * self._steps[None]
            distance2 = np.sum((nearest - chunk[:, None, :]) ** 2, axis=2)
            best = np.argmin(distance2, axis=1)
            rows = np.arange(len(chunk))
            x_out[which] = self.x_m[best] + fraction[rows, best] * (
                self.x_m[best + 1] - self.x_m[best]
            )
            offset_out[which] = np.sqrt(distance2[rows, best])
        finite = np.isfinite(x_out) & np.isfinite(offset_out)
        inside = (x_out > self.x_m[0]) & (x_out < self.x_m[-1])
        on = finite & inside & (offset_out <= self.max_offset_m)
        if heading_deg is not None:
            heading = np.broadcast_to(np.asarray(heading_deg, dtype=np.float64), x_out.shape)
            along = self.heading_deg(np.where(finite, x_out, self.x_m[0]))
            difference = np.abs((heading - along + 180.0) % 360.0 - 180.0)
            on &= ~(difference > MAX_HEADING_DIFFERENCE_DEG)  # NaN (unknown) passes
        return Located(x_out, offset_out, on)

    def locate_fix(
        self, lat: float, lon: float, heading_deg: float | None = None
    ) -> tuple[float, float, bool]:
        """One fix: (x_m, offset_m, on_corridor), the same answer as `locate` for it.

        The car map-matches one fix per control step (10 Hz); for one point numpy's per-call
        overhead is most of `locate`'s cost, so this walks its grid cell's few sub-segments in
        plain floats. A fix its cell does not resolve (off the corridor, outside the grid, not a
        number) goes through `locate`.
        """
        east = math.radians(lon - self._lon0) * EARTH_RADIUS_M * self._cos_lat0
        north = math.radians(lat - self._lat0) * EARTH_RADIUS_M
        best: tuple[float, int, float] | None = None
        if math.isfinite(east) and math.isfinite(north):
            column = math.floor((east - self._grid_low_east) / self._cell_m)
            row = math.floor((north - self._grid_low_north) / self._cell_m)
            if 0 <= column < self._grid_columns and 0 <= row < self._grid_rows:
                for index in self._cell_lists[column * self._grid_rows + row]:
                    start_east, start_north, step_east, step_north, step_len2 = self._segments[
                        index
                    ]
                    rel_east, rel_north = east - start_east, north - start_north
                    fraction = (rel_east * step_east + rel_north * step_north) / step_len2
                    fraction = min(max(fraction, 0.0), 1.0)
                    gap_east = start_east + fraction * step_east - east
                    gap_north = start_north + fraction * step_north - north
                    distance2 = gap_east * gap_east + gap_north * gap_north
                    if best is None or distance2 < best[0]:  # ties: the lower index, as argmin
                        best = (distance2, index, fraction)
        if best is None or best[0] > self.max_offset_m**2:
            located = self.locate(lat, lon, heading_deg)
            return float(located.x_m[0]), float(located.offset_m[0]), bool(located.on_corridor[0])
        distance2, index, fraction = best
        x_m = self._vertex_x[index] + fraction * (self._vertex_x[index + 1] - self._vertex_x[index])
        on = self._vertex_x[0] < x_m < self._vertex_x[-1]
        if on and heading_deg is not None and not math.isnan(heading_deg):
            along = self._segment_heading_deg(x_m)
            difference = abs((heading_deg - along + 180.0) % 360.0 - 180.0)
            on = difference <= MAX_HEADING_DIFFERENCE_DEG
        return x_m, math.sqrt(distance2), on

    def _segment_heading_deg(self, x_m: float) -> float:
        """`heading_deg` for one position, in plain floats."""
        index = min(max(bisect.bisect_right(self._vertex_x, x_m) - 1, 0), len(self._segments) - 1)
        _, _, step_east, step_north, _ = self._segments[index]
        return math.degrees(math.atan2(step_east, step_north)) % 360.0

    def _build_index(self) -> None:
        """List, per square cell of a grid over the corridor, the sub-segments near it.

        A sub-segment is listed for a cell when it passes within max_offset_m + half the
        cell's diagonal (+1 m for rounding) of the cell's centre, so it is listed for every
        cell holding a point within max_offset_m of it. The cell edge grows with the corridor
        to keep the table small.
        """
        reach = self.max_offset_m
        low = self._points.min(axis=0) - reach
        span = self._points.max(axis=0) + reach - low
        cell_m = _CELL_M
        while np.prod(np.ceil(span / cell_m) + 1) * len(self._starts) > _INDEX_ELEMENTS:
            cell_m *= 2
        shape = (np.ceil(span / cell_m) + 1).astype(np.int64)
        columns, rows = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
        centres = low + (np.column_stack([columns.ravel(), rows.ravel()]) + 0.5) * cell_m
        relative = centres[:, None, :] - self._starts[None, :, :]
        fraction = np.clip(
            np.einsum("pij,ij->pi", relative, self._steps) / self._step_len2, 0.0, 1.0
        )
        nearest = self._starts[None] + fraction[..., None] * self._steps[None]
        distance2 = np.sum((nearest - centres[:, None, :]) ** 2, axis=2)
        near = distance2 <= (reach + cell_m * math.sqrt(0.5) + 1.0) ** 2
        counts = near.sum(axis=1)
        candidates = np.zeros((len(centres), max(1, int(counts.max()))), dtype=np.int64)
        for cell in np.flatnonzero(counts):
            listed = np.flatnonzero(near[cell])  # ascending: argmin ties break as above
            candidates[cell, : len(listed)] = listed
        self._cell_m = cell_m
        self._grid_low = low
        self._grid_shape = shape
        self._candidates = candidates
        self._candidate_counts = counts
        # The same index in plain Python for `locate_fix`.
        self._grid_low_east, self._grid_low_north = float(low[0]), float(low[1])
        self._grid_columns, self._grid_rows = int(shape[0]), int(shape[1])
        self._cell_lists = [
            tuple(int(index) for index in candidates[cell, :count])
            for cell, count in enumerate(counts)
        ]
        self._segments = [
            (float(start[0]), float(start[1]), float(step[0]), float(step[1]), float(length2))
            for start, step, length2 in zip(self._starts, self._steps, self._step_len2, strict=True)
        ]
        self._vertex_x = [float(x) for x in self.x_m]

    def _locate_by_cell(
        self, points: FloatArray, x_out: FloatArray, offset_out: FloatArray
    ) -> NDArray[np.bool_]:
        """Fill x_out/offset_out for the fixes resolved by their cell's list; returns which."""
        resolved = np.zeros(len(points), dtype=bool)
        with np.errstate(invalid="ignore"):
            cell_xy = np.floor((points - self._grid_low) / self._cell_m)
        in_grid = np.all(np.isfinite(cell_xy), axis=1)
        in_grid[in_grid] = np.all(
            (cell_xy[in_grid] >= 0) & (cell_xy[in_grid] < self._grid_shape), axis=1
        )
        which = np.flatnonzero(in_grid)
        cells = cell_xy[which, 0].astype(np.int64) * self._grid_shape[1] + cell_xy[which, 1].astype(
            np.int64
        )
        counts = self._candidate_counts[cells]
        which, cells, counts = which[counts > 0], cells[counts > 0], counts[counts > 0]
        if len(which) == 0:
            return resolved
        chunk = points[which]
        listed = self._candidates[cells]
        starts = self._starts[listed]
        steps = self._steps[listed]
        relative = chunk[:, None, :] - starts
        fraction = np.einsum("pkj,pkj->pk", relative, steps) / self._step_len2[listed]
        fraction = np.clip(fraction, 0.0, 1.0)
        nearest = starts + fraction[..., None] * steps
        distance2 = np.sum((nearest - chunk[:, None, :]) ** 2, axis=2)
        distance2[np.arange(listed.shape[1])[None, :] >= counts[:, None]] = np.inf
        best_k = np.argmin(distance2, axis=1)
        rows = np.arange(len(chunk))
        best_distance2 = distance2[rows, best_k]
        near = best_distance2 <= self.max_offset_m**2
        best = listed[rows, best_k][near]
        done = which[near]
        x_out[done] = self.x_m[best] + fraction[rows, best_k][near] * (
            self.x_m[best + 1] - self.x_m[best]
        )
        offset_out[done] = np.sqrt(best_distance2[near])
        resolved[done] = True
        return resolved

    def position(self, x_m: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Latitude and longitude at positions x_m (linear between vertices)."""
        x = np.asarray(x_m, dtype=np.float64)
        return np.interp(x, self.x_m, self.lat), np.interp(x, self.x_m, self.lon)

    def heading_deg(self, x_m: ArrayLike) -> FloatArray:
        """Direction of travel (degrees clockwise from north) at positions x_m."""
        x = np.atleast_1d(np.asarray(x_m, dtype=np.float64))
        index = np.clip(np.searchsorted(self.x_m, x, side="right") - 1, 0, len(self._steps) - 1)
        east, north = self._steps[index, 0], self._steps[index, 1]
        heading: FloatArray = np.degrees(np.arctan2(east, north)) % 360.0
        return heading
