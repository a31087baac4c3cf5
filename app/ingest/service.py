"""The ping ingest: body -> checks -> group-committed rows -> the request's counts."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from datetime import datetime

from fastapi import FastAPI
from sqlalchemy.ext.asyncio import AsyncEngine

from app.auth import Principal
from app.core import metrics
from app.core.config import Settings
from app.core.logs import RepeatedMessages
from app.ingest.directory import FleetDirectoryCache
from app.ingest.pings import (
    BodyError,
    ForeignVehicle,
    Rejected,
    TimeWindow,
    check_in_context,
    read_pings,
)
from app.ingest.writer import PingKey, PingWriter, RefusedByDatabase, UnstorableValue

log = logging.getLogger(__name__)
log.addFilter(RepeatedMessages())  # a car resending its spool is one line a window


class RowsRefused(RuntimeError):
    """The database refused rows that passed every check, even with a fresh roster (409)."""


@dataclass(frozen=True)
class IngestResult:
    """One request's answer: rows committed, duplicates (of which `conflicts` said something
    else than the ping kept at their vehicle_id and ts), per-item rejections."""

    accepted: int
    duplicates: int
    conflicts: int
    rejected: list[Rejected]


def _log_conflicts(conflicts: tuple[PingKey, ...]) -> None:
    """A warning per vehicle whose pings reused a stored ping's ts with other content: its clock
    repeats or jumps back, and what it sent at those instants was not stored."""
    by_vehicle: dict[str, list[PingKey]] = {}
    for key in conflicts:
        by_vehicle.setdefault(key[0], []).append(key)
    for vehicle_id, keys in by_vehicle.items():
        log.warning(
            "vehicle %s sent %d ping(s) at a ts already stored with other content (first %s): "
            "its clock may repeat or jump back; the stored pings are kept, these are not",
            vehicle_id,
            len(keys),
            min(ts for _, ts in keys).isoformat(),
        )


@dataclass(frozen=True)
class Ingest:
    """The process's ingest machinery: the fleet directory and the ping writer."""

    directory: FleetDirectoryCache
    writer: PingWriter
    retention_days: int
    max_future_s: float

    async def pings(self, body: bytes, principal: Principal, received_at: datetime) -> IngestResult:
        """Store the body's good pings; BodyError (422) or ForeignVehicle (403) refuse it all."""
        try:
            pings, rejected_fields = read_pings(body, principal)
        except ForeignVehicle as refusal:
            metrics.PINGS_REFUSED.inc(refusal.pings)
            raise
        # each car's newest config version among its pings (versions start at 1)
        config_versions: dict[str, int] = {}
        for _, ping in pings:
            if ping.config_version is not None:
                newest = max(config_versions.get(ping.vehicle_id, 0), ping.config_version)
                config_versions[ping.vehicle_id] = newest
        directory = await self.directory.directory(
            {ping.vehicle_id for _, ping in pings}, config_versions=config_versions
        )
        window = TimeWindow.around(
            received_at, retention_days=self.retention_days, max_future_s=self.max_future_s
        )
        rows, rejected_context = check_in_context(pings, directory, window, received_at)
        try:
            outcome = await self.writer.write(rows)
        except UnstorableValue as error:
            metrics.PINGS_REFUSED.inc(len(pings))
            raise BodyError(
                f"a value cannot be stored: {error}; nothing of this request was stored"
            ) from None
        except RefusedByDatabase:
            # The roster changed under the cache (a vehicle removed): check again with a fresh
            # directory, so the removed vehicle's pings become per-item rejections.
            directory = await self.directory.directory(reload=True)
            rows, rejected_context = check_in_context(pings, directory, window, received_at)
            try:
                outcome = await self.writer.write(rows)
            except RefusedByDatabase as error:
                raise RowsRefused(f"refused by the database: {error}") from None
        rejected = sorted(rejected_fields + rejected_context, key=lambda r: r.index)
        # A zero is not counted: in multiprocess mode every increment writes the shared file.
        if outcome.accepted:
            metrics.PINGS_ACCEPTED.inc(outcome.accepted)
        if outcome.duplicates:
            metrics.PINGS_DUPLICATE.inc(outcome.duplicates)
        if rejected:
            metrics.PINGS_REJECTED.inc(len(rejected))
        if outcome.conflicts:
            _log_conflicts(outcome.conflicts)
        return IngestResult(outcome.accepted, outcome.duplicates, len(outcome.conflicts), rejected)


@asynccontextmanager
async def ingest_running(
    app: FastAPI, engine: AsyncEngine, settings: Settings
) -> AsyncIterator[None]:
    """Run the ingest machinery for the app's lifetime (app.state.ingest)."""
    writer = PingWriter(engine, concurrency=settings.ingest_write_concurrency)
    directory = FleetDirectoryCache(
        engine, settings.roster_cache_ttl_s, retention_days=settings.ping_retention_days
    )
    app.state.ingest = Ingest(
        directory=directory,
        writer=writer,
        retention_days=settings.ping_retention_days,
        max_future_s=settings.ping_max_future_s,
    )
    writer.start()
    try:
        yield
    finally:
        await writer.stop()
        await directory.close(settings.db_connect_timeout_s)
