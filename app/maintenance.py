"""Housekeeping of the warehouse: ping partitions ahead of time, old ones dropped.

Runs at server start-up, every hour inside the server, and on `smoothfleet db maintain`.
The SQL functions it calls are defined in migration 0001.

Retention also reaches status reports (`fact_vehicle_status`, accepted only within the same
window) and the DEFAULT partition. Partitions are made from yesterday on, so a ping
of an earlier day (a car's spool uploaded after a week offline, a server down for a week) waits
there, and no partition of its day is ever made to move it into: without this, such rows would
outlive every retention window.
"""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import Connection, text
from sqlalchemy.ext.asyncio import AsyncConnection

# Today's date in UTC, whatever the session's time zone: partitions are UTC days, and a session
# need not be in UTC (libpq's PGTZ overrides the engine's `timezone=UTC`), so `current_date`
# could drop or delete a day early or keep one late.
UTC_TODAY = "(now() AT TIME ZONE 'UTC')::date"
ENSURE_SQL = text(
    f"SELECT ensure_ping_partitions({UTC_TODAY} - 1, {UTC_TODAY} + CAST(:ahead AS integer))"
)
RETENTION_SQL = text(
    f"SELECT drop_ping_partitions_before({UTC_TODAY} - CAST(:keep_days AS integer))"
)
# Workers and replicas each run the pass (at start-up, then hourly): one at a time, or two
# reaching a new day together both created its partition and the later failed whole (a unique
# violation in PostgreSQL's catalog), its retention rolled back with it.
MAINTENANCE_LOCK_SQL = text("SELECT pg_advisory_xact_lock(hashtext('smoothfleet-maintenance'))")
# Rows past retention, deleted where whole days cannot be dropped: the status reports (one table)
# and the pings that wait in the default partition.
RETENTION_DELETE_SQL = (
    "DELETE FROM {table} "
    f"WHERE ts < ({UTC_TODAY} - CAST(:keep_days AS integer))::timestamp AT TIME ZONE 'UTC'"
)
STATUS_RETENTION_SQL = text(RETENTION_DELETE_SQL.format(table="fact_vehicle_status"))
DEFAULT_RETENTION_SQL = text(RETENTION_DELETE_SQL.format(table="fact_vehicle_ping_default"))
# A client address's failed logins on an account, kept while they slow it down (at most 5 min
# after its last failure) and a day beyond: a guesser rotating addresses adds a row an attempt.
LOGIN_FAILURES_SQL = text(
    "DELETE FROM ops_login_failure WHERE last_failed_at < now() - interval '1 day'"
)


@dataclass(frozen=True)
class MaintenanceResult:
    """Partitions created and dropped by one pass."""

    partitions_created: int
    partitions_dropped: int
    default_rows_deleted: int
    status_reports_deleted: int
    login_failures_deleted: int


def maintain(connection: Connection, *, ahead_days: int, retention_days: int) -> MaintenanceResult:
    """Create the coming days' ping partitions and drop those past retention, and delete the
    rows past retention that wait in the default partition, the status reports past it, and
    the failed logins of addresses that have not failed for a day."""
    keep = {"keep_days": retention_days}
    connection.execute(MAINTENANCE_LOCK_SQL)
    created = connection.execute(ENSURE_SQL, {"ahead": ahead_days}).scalar_one()
    dropped = connection.execute(RETENTION_SQL, keep).scalar_one()
    deleted = connection.execute(DEFAULT_RETENTION_SQL, keep).rowcount
    reports = connection.execute(STATUS_RETENTION_SQL, keep).rowcount
    logins = connection.execute(LOGIN_FAILURES_SQL).rowcount
    return MaintenanceResult(int(created), int(dropped), int(deleted), int(reports), int(logins))


async def maintain_async(
    connection: AsyncConnection, *, ahead_days: int, retention_days: int
) -> MaintenanceResult:
    """The same pass on the server's asynchronous engine."""
    return await connection.run_sync(
        lambda sync: maintain(sync, ahead_days=ahead_days, retention_days=retention_days)
    )
