"""What ingest must know about the fleet, cached per process: vehicle -> corridor -> geometry.

Every ping needs its vehicle's corridor (lanes, map-matching geometry); asking the database per
ping would double the work of the hot path, so the directory is loaded once and refreshed every
`roster_cache_ttl_s`. A vehicle added to the roster is seen at once: an unknown vehicle_id makes
the request reload the directory, at most once per `MIN_RELOAD_INTERVAL_S` so that a stream of
bad ids cannot turn into a stream of queries. A request that meets an unknown id sooner after a
load waits for the next reload rather than answering "unknown vehicle" from a snapshot older
than the car: the agent drops the pings the server rejects, so a car added just after a reload
would lose its first ones. A ping naming its car's config version (`contract.vehicles.Ping`)
newer than the snapshot's reloads it the same way: the car was moved since, and judged on the
corridor it left its ping would be refused or stored off the road. In the last
`REFRESH_AHEAD_SHARE` of a snapshot's life the next request starts its reload in the background
and goes on with the snapshot, so under traffic no request waits for a reload (every request in
flight used to wait for one every `roster_cache_ttl_s`: a stall in the ingest tail,
docs/performance.md).

A car spools its pings while offline and sends them later, possibly after an operator moved it
to another corridor: each ping is checked and map-matched on the corridor the car was assigned
at the ping's `ts` (`dim_vehicle_assignment`, migration 0012), as the analytics views read it,
not on today's, which would refuse its lane for good or place it on the wrong road. Only the
corridor changes that ended within the ping retention window are loaded: an older assignment
can hold no ping that ingest still accepts, and the table keeps every change forever.
"""

from __future__ import annotations

import asyncio
import time
from bisect import bisect_right
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import text
from sqlalchemy.ext.asyncio import AsyncEngine

from contract.corridor import MIN_SPEED_FOR_HEADING_MPS, CorridorGeometry

MIN_RELOAD_INTERVAL_S = 2.0
REFRESH_AHEAD_SHARE = 0.2
# Corridor changes loaded beyond the retention window: a request that waited for a load arrived
# before it, and a wall clock may step back; a day more of history costs next to nothing.
HISTORY_MARGIN = timedelta(days=1)

VEHICLES_SQL = text("SELECT vehicle_id, corridor_id, config_version FROM dim_vehicle")
# The end of each corridor a vehicle was assigned before its current one, if the assignment
# ended after `since`: a row whose next row names the same corridor (a change of lane or route
# only) is no end of a corridor. The window function sees the later rows (valid_to > since
# holds for them too), and the open row (valid_to = infinity, no next row) is never one.
CORRIDOR_ENDS_SQL = text(
    "SELECT vehicle_id, valid_to, corridor_id FROM ("
    " SELECT vehicle_id, valid_to, corridor_id,"
    " lead(corridor_id) OVER (PARTITION BY vehicle_id ORDER BY valid_from) AS next_corridor_id"
    " FROM dim_vehicle_assignment WHERE valid_to > :since"
    ") spans WHERE next_corridor_id <> corridor_id ORDER BY vehicle_id, valid_to"
)
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
class CorridorEnds:
    """A vehicle's earlier corridors: `corridor_ids[i]` was assigned until `ends[i]` (from
    `ends[i - 1]`; the first from before the retention window), in time order."""

    ends: tuple[datetime, ...]
    corridor_ids: tuple[str, ...]


@dataclass(frozen=True)
class FleetDirectory:
    """A snapshot of the roster, the recent corridor changes and the corridors."""

    vehicle_corridor: dict[str, str] = field(default_factory=dict)
    # each vehicle's config version when loaded: a ping naming a newer one was taken under an
    # assignment this snapshot does not know
    config_versions: dict[str, int] = field(default_factory=dict)
    # only the vehicles moved to another corridor within the retention window: most have none
    earlier_corridors: dict[str, CorridorEnds] = field(default_factory=dict)
    corridors: dict[str, CorridorInfo] = field(default_factory=dict)

    def corridor_of(self, vehicle_id: str, ts: datetime) -> CorridorInfo | None:
        """The corridor a known vehicle was assigned at `ts`, or None for an unknown vehicle.

        Spans are half-open, [valid_from, valid_to), and the boundary is judged on two clocks,
        as the analytics views judge it: `ts` is the car's GPS clock, a change's time the
        database server's clock when it was made. So the pings a car takes between the change
        and its next config fetch (seconds later) count on the new corridor. A `ts` before the
        loaded history (older than the retention window: refused anyway) gets the earliest
        corridor loaded.
        """
        corridor_id = self.vehicle_corridor.get(vehicle_id)
        if corridor_id is None:
            return None
        earlier = self.earlier_corridors.get(vehicle_id)
        if earlier is not None:
            index = bisect_right(earlier.ends, ts)
            if index < len(earlier.ends):
                corridor_id = earlier.corridor_ids[index]
        return self.corridors.get(corridor_id)


class FleetDirectoryCache:
    """Loads the directory on demand and keeps it `ttl_s` seconds; the corridor changes of the
    last `retention_days` (the pings' retention window) with it."""

    def __init__(
        self,
        engine: AsyncEngine,
        ttl_s: float,
        *,
        retention_days: int,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._engine = engine
        self._ttl_s = ttl_s
        self._retention = timedelta(days=retention_days)
        self._clock = clock
        self._directory: FleetDirectory | None = None
        self._loaded_at = -float("inf")
        self._lock = asyncio.Lock()
        self._refresh: asyncio.Task[FleetDirectory] | None = None
        # Config versions pings named that a reload found the roster still behind (a database
        # restored from an older backup): no reason to load again for them.
        self._ahead: dict[str, int] = {}

    async def directory(
        self,
        vehicle_ids: Collection[str] = (),
        *,
        config_versions: Mapping[str, int] | None = None,
        reload: bool = False,
    ) -> FleetDirectory:
        """A fresh enough directory that knows `vehicle_ids` if the roster does, and each
        vehicle's assignment as of at least the config version `config_versions` names."""
        current = self._directory
        now = self._clock()
        age = now - self._loaded_at
        if not reload and current is not None and age < self._ttl_s:
            if any(v not in current.vehicle_corridor for v in vehicle_ids) or self._behind(
                current, config_versions
            ):
                if age < MIN_RELOAD_INTERVAL_S:
                    await asyncio.sleep(MIN_RELOAD_INTERVAL_S - age)
                    now = self._clock()
                fresh = await self._reload(now)
                self._remember_ahead(fresh, config_versions)
                return fresh
            if age > self._ttl_s * (1 - REFRESH_AHEAD_SHARE) and self._refresh is None:
                self._refresh = asyncio.create_task(self._reload(now))
                self._refresh.add_done_callback(self._refresh_done)
            return current
        return await self._reload(now)

    def _behind(self, directory: FleetDirectory, config_versions: Mapping[str, int] | None) -> bool:
        """Whether a ping names a config version of a known vehicle newer than the snapshot's
        (and than any a reload already failed to find)."""
        if not config_versions:
            return False
        known = directory.config_versions
        return any(
            version > known.get(vehicle, version) and version > self._ahead.get(vehicle, -1)
            for vehicle, version in config_versions.items()
        )

    def _remember_ahead(
        self, directory: FleetDirectory, config_versions: Mapping[str, int] | None
    ) -> None:
        for vehicle, version in (config_versions or {}).items():
            if version > directory.config_versions.get(vehicle, version):
                self._ahead[vehicle] = max(version, self._ahead.get(vehicle, -1))

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
        # On this process's wall clock, as each request's window (from its received_at) is.
        since = datetime.now(UTC) - self._retention - HISTORY_MARGIN
        async with self._engine.connect() as connection:
            vehicles = (await connection.execute(VEHICLES_SQL)).all()
            ends = (await connection.execute(CORRIDOR_ENDS_SQL, {"since": since})).all()
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
        by_vehicle: dict[str, list[tuple[datetime, str]]] = {}
        for row in ends:
            by_vehicle.setdefault(str(row.vehicle_id), []).append(
                (row.valid_to, str(row.corridor_id))
            )
        return FleetDirectory(
            vehicle_corridor={str(row.vehicle_id): str(row.corridor_id) for row in vehicles},
            config_versions={str(row.vehicle_id): int(row.config_version) for row in vehicles},
            earlier_corridors={
                vehicle_id: CorridorEnds(
                    tuple(end for end, _ in spans), tuple(corridor for _, corridor in spans)
                )
                for vehicle_id, spans in by_vehicle.items()
            },
            corridors=infos,
        )
