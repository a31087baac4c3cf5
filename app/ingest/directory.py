"""What ingest must know about the fleet, cached per process: vehicle -> corridor -> geometry.

Every ping needs its vehicle's corridor (lanes, map-matching geometry); asking the database per
ping would double the work of the hot path, so the directory is loaded once and refreshed every
`roster_cache_ttl_s`. A vehicle added to the roster is seen at once: an unknown vehicle_id makes
the request reload the directory, at most once per `MIN_RELOAD_INTERVAL_S` so that a stream of
bad ids cannot turn into a stream of queries. A request that meets an unknown id sooner after a
load waits for the next reload rather than answering "unknown vehicle" from a snapshot older
than the car: the agent drops the pings the server rejects, so a car added just after a reload
would lose its first ones. In the last `REFRESH_AHEAD_SHARE` of a snapshot's
life the next request starts its reload in the background and goes on with the snapshot, so
under traffic no request waits for a reload (every request in flight used to wait for one
every `roster_cache_ttl_s`: a stall in the ingest tail, docs/performance.md).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import text
from sqlalchemy.ext.asyncio import AsyncEngine

from contract.corridor import MIN_SPEED_FOR_HEADING_MPS, CorridorGeometry

MIN_RELOAD_INTERVAL_S = 2.0
REFRESH_AHEAD_SHARE = 0.2

VEHICLES_SQL = text("SELECT vehicle_id, corridor_id FROM dim_vehicle")
CORRIDORS_SQL = text("SELECT corridor_id, lanes FROM dim_corridor")
SEGMENTS_SQL = text(
    "SELECT corridor_id, start_x_m, end_x_m, start_lat, start_lon, end_lat, end_lon "
    "FROM dim_i24_segment ORDER BY corridor_id, start_x_m"
)


@dataclass(frozen=True)
class CorridorInfo:
    """A corridor's lane count and its geometry (None when it has no sub-segments yet)."""

    corridor_id: str
    lanes: int
    geometry: CorridorGeometry | None

    def x_m(
        self,
        lat: NDArray[np.float64],
        lon: NDArray[np.float64],
        heading_deg: NDArray[np.float64] | None = None,
    ) -> list[float | None]:
        """Map-matched positions of the fixes; None where a fix is off the corridor (or, with
        trusted headings, driving the other way)."""
        if self.geometry is None:
            return [None] * len(lat)
        located = self.geometry.locate(lat, lon, heading_deg)
        return [
            float(x) if on else None
            for x, on in zip(located.x_m.tolist(), located.on_corridor.tolist(), strict=True)
        ]

    def x_m_of_fix(
        self, lat: float, lon: float, heading_deg: float | None, speed_mps: float
    ) -> float | None:
        """`x_m` for one fix in plain floats (a lone ping: numpy's per-call overhead would be
        most of the cost), its heading trusted as `contract.corridor.trusted_heading` does."""
        if self.geometry is None:
            return None
        trusted = heading_deg if speed_mps >= MIN_SPEED_FOR_HEADING_MPS else None
        x_m, _, on = self.geometry.locate_fix(lat, lon, trusted)
        return x_m if on else None


@dataclass(frozen=True)
class FleetDirectory:
    """A snapshot of the roster and corridors."""

    vehicle_corridor: dict[str, str] = field(default_factory=dict)
    corridors: dict[str, CorridorInfo] = field(default_factory=dict)

    def corridor_of(self, vehicle_id: str) -> CorridorInfo | None:
        """The corridor a known vehicle drives, or None for an unknown vehicle."""
        corridor_id = self.vehicle_corridor.get(vehicle_id)
        return None if corridor_id is None else self.corridors.get(corridor_id)


class FleetDirectoryCache:
    """Loads the directory on demand and keeps it `ttl_s` seconds."""

    def __init__(
        self, engine: AsyncEngine, ttl_s: float, *, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self._engine = engine
        self._ttl_s = ttl_s
        self._clock = clock
        self._directory: FleetDirectory | None = None
        self._loaded_at = -float("inf")
        self._lock = asyncio.Lock()
        self._refresh: asyncio.Task[FleetDirectory] | None = None

    async def directory(
        self, vehicle_ids: Collection[str] = (), *, reload: bool = False
    ) -> FleetDirectory:
        """A fresh enough directory that knows `vehicle_ids` if the roster does."""
        current = self._directory
        now = self._clock()
        age = now - self._loaded_at
        if not reload and current is not None and age < self._ttl_s:
            if any(v not in current.vehicle_corridor for v in vehicle_ids):
                if age < MIN_RELOAD_INTERVAL_S:
                    await asyncio.sleep(MIN_RELOAD_INTERVAL_S - age)
                    now = self._clock()
                return await self._reload(now)
            if age > self._ttl_s * (1 - REFRESH_AHEAD_SHARE) and self._refresh is None:
                self._refresh = asyncio.create_task(self._reload(now))
                self._refresh.add_done_callback(self._refresh_done)
            return current
        return await self._reload(now)

    async def close(self, timeout_s: float) -> None:
        """Give a background reload up to `timeout_s` to finish (at shutdown, before the engine
        is disposed: a reload dropped mid-query would leave its connection to the garbage
        collector). Not longer: a frozen database must not hold the shutdown."""
        refresh = self._refresh
        if refresh is not None:
            await asyncio.wait({refresh}, timeout=timeout_s)

    async def _reload(self, requested_at: float) -> FleetDirectory:
        async with self._lock:
            # Another request may have reloaded while this one waited for the lock.
            if self._directory is not None and self._loaded_at >= requested_at:
                return self._directory
            self._directory = await self._load()
            self._loaded_at = self._clock()
            return self._directory

    def _refresh_done(self, task: asyncio.Task[FleetDirectory]) -> None:
        self._refresh = None
        if not task.cancelled():
            # A failed background reload changes nothing: the snapshot lives out its TTL and
            # the first request after that reloads itself (and meets the error).
            task.exception()

    async def _load(self) -> FleetDirectory:
        async with self._engine.connect() as connection:
            vehicles = (await connection.execute(VEHICLES_SQL)).all()
            corridors = (await connection.execute(CORRIDORS_SQL)).all()
            segments = (await connection.execute(SEGMENTS_SQL)).mappings().all()
        by_corridor: dict[str, list[dict[str, float]]] = {}
        for segment in segments:
            by_corridor.setdefault(segment["corridor_id"], []).append(dict(segment))
        infos = {}
        for corridor_id, lanes in corridors:
            pieces = by_corridor.get(corridor_id)
            geometry = (
                CorridorGeometry.from_segments(corridor_id, int(lanes), pieces) if pieces else None
            )
            infos[corridor_id] = CorridorInfo(corridor_id, int(lanes), geometry)
        return FleetDirectory(
            vehicle_corridor={str(row.vehicle_id): str(row.corridor_id) for row in vehicles},
            corridors=infos,
        )
