"""Corridor geometry: map a GPS fix to its position x_m along a corridor, and back.

Shared by the car (geofence, plan lookup) and the server (ping map-matching, observations,
simulated fleets). It lives with the agent because the agent never imports the server, and it
needs nothing but numpy.

The corridor is the polyline through its sub-segments' end points (<= 100 m apart on the seed
corridor, so the chord error on highway curves is a few metres). Positions are projected in a
local equirectangular plane, which is exact to well under a metre over a few tens of km.
"""

from __future__ import annotations

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
# Points projected per block: bounds the (points x segments) work array to a few MB.
_BLOCK_ELEMENTS = 2_000_000

FloatArray = NDArray[np.float64]


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

    @classmethod
    def from_segments(
        cls, corridor_id: str, lanes: int, segments: Sequence[Mapping[str, Any]]
    ) -> CorridorGeometry:
        """Build from ordered sub-segments with start/end x_m, lat and lon."""
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

    def locate(self, lat: ArrayLike, lon: ArrayLike) -> Located:
        """Project fixes onto the corridor (vectorised over fixes)."""
        lat_a = np.atleast_1d(np.asarray(lat, dtype=np.float64))
        lon_a = np.atleast_1d(np.asarray(lon, dtype=np.float64))
        points = self._to_plane(lat_a, lon_a)
        x_out = np.empty(len(points))
        offset_out = np.empty(len(points))
        block = max(1, _BLOCK_ELEMENTS // len(self._starts))
        for first in range(0, len(points), block):
            chunk = points[first : first + block]
            relative = chunk[:, None, :] - self._starts[None, :, :]
            fraction = np.einsum("pij,ij->pi", relative, self._steps) / self._step_len2
            fraction = np.clip(fraction, 0.0, 1.0)
            nearest = self._starts[None] + fraction[..., None] * self._steps[None]
            distance2 = np.sum((nearest - chunk[:, None, :]) ** 2, axis=2)
            best = np.argmin(distance2, axis=1)
            rows = np.arange(len(chunk))
            x_out[first : first + block] = self.x_m[best] + fraction[rows, best] * (
                self.x_m[best + 1] - self.x_m[best]
            )
            offset_out[first : first + block] = np.sqrt(distance2[rows, best])
        finite = np.isfinite(x_out) & np.isfinite(offset_out)
        inside = (x_out > self.x_m[0]) & (x_out < self.x_m[-1])
        on = finite & inside & (offset_out <= self.max_offset_m)
        return Located(x_out, offset_out, on)

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
