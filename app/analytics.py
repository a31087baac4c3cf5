"""The analytics views (schema `analytics`, migration 0002) as pandas DataFrames, and CSV export.

The SQL is the single definition of every figure (docs/analytics.md); this module only names the
views, filters them by time or vehicle, and hands the rows to pandas. Times come back as
timezone-aware UTC timestamps.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import date, datetime
from typing import IO, Any

import pandas as pd
from sqlalchemy import Connection, text


class UnknownView(ValueError):
    """The name is not one of the analytics views; the message lists the known ones."""


@dataclass(frozen=True)
class AnalyticsView:
    """A view of the analytics schema: what one row is, and its time column for --since/--until."""

    name: str
    grain: str
    time_column: str
    has_vehicle: bool


VIEWS: dict[str, AnalyticsView] = {
    view.name: view
    for view in (
        AnalyticsView("engagement_daily", "vehicle x UTC day", "day", True),
        AnalyticsView("engagement_fleet_daily", "UTC day", "day", False),
        AnalyticsView("ping_rate_hourly", "vehicle x UTC hour", "hour", True),
        AnalyticsView("fleet_ping_hourly", "UTC hour", "hour", False),
        AnalyticsView("inrix_latency", "corridor x INRIX snapshot", "measured_at", False),
        AnalyticsView("plan_adherence", "ping following a plan", "ts", True),
        AnalyticsView("plan_adherence_daily", "vehicle x UTC day", "day", True),
        AnalyticsView("edie_boxes", "corridor x 10 s x 200 m box", "t_start", False),
    )
}

# The paper's box size ("Results": h_t = 10 s, h_x = 200 m).
EDIE_H_T_S = 10.0
EDIE_H_X_M = 200.0


def view(name: str) -> AnalyticsView:
    """The view called `name`, or UnknownView naming the choices."""
    try:
        return VIEWS[name]
    except KeyError:
        known = ", ".join(sorted(VIEWS))
        raise UnknownView(f"unknown analytics view {name!r}; choose one of: {known}") from None


def _bound(value: datetime | date, column: str) -> datetime | date:
    """Day columns compare with dates; a datetime bound is cut to its UTC day there."""
    if column == "day" and isinstance(value, datetime):
        return value.date()
    return value


def view_query(
    name: str,
    *,
    since: datetime | date | None = None,
    until: datetime | date | None = None,
    vehicle_id: str | None = None,
) -> tuple[str, dict[str, Any]]:
    """SQL and parameters selecting a view's rows in [since, until) (and for one vehicle)."""
    chosen = view(name)
    if vehicle_id is not None and not chosen.has_vehicle:
        raise UnknownView(f"analytics view {name} has no vehicle_id column")
    params: dict[str, Any] = {}
    if name == "edie_boxes":
        # The view is the function over all time; a window goes to the function itself, which
        # then reads only that window's pings (partition pruning, no full scan).
        params = {
            "since": since if since is not None else "-infinity",
            "until": until if until is not None else "infinity",
        }
        return (
            "SELECT * FROM analytics.edie_field(CAST(:since AS timestamptz), "
            "CAST(:until AS timestamptz)) ORDER BY corridor_id, t_start, x_start_m",
            params,
        )
    conditions: list[str] = []
    if since is not None:
        conditions.append(f"{chosen.time_column} >= :since")
        params["since"] = _bound(since, chosen.time_column)
    if until is not None:
        conditions.append(f"{chosen.time_column} < :until")
        params["until"] = _bound(until, chosen.time_column)
    if vehicle_id is not None:
        conditions.append("vehicle_id = :vehicle_id")
        params["vehicle_id"] = vehicle_id
    where = f" WHERE {' AND '.join(conditions)}" if conditions else ""
    order = f"vehicle_id, {chosen.time_column}" if chosen.has_vehicle else chosen.time_column
    if name == "inrix_latency":
        order = "corridor_id, measured_at"
    return f"SELECT * FROM analytics.{name}{where} ORDER BY {order}", params


def read_view(
    connection: Connection,
    name: str,
    *,
    since: datetime | date | None = None,
    until: datetime | date | None = None,
    vehicle_id: str | None = None,
) -> pd.DataFrame:
    """One analytics view as a DataFrame (optionally a time window and one vehicle)."""
    sql, params = view_query(name, since=since, until=until, vehicle_id=vehicle_id)
    return _frame(connection, sql, params)


def edie_field(
    connection: Connection,
    since: datetime,
    until: datetime,
    *,
    h_t_s: float = EDIE_H_T_S,
    h_x_m: float = EDIE_H_X_M,
) -> pd.DataFrame:
    """Edie's fields of the pings in [since, until) on h_t x h_x boxes (paper, Results)."""
    if h_t_s <= 0 or h_x_m <= 0:
        raise ValueError("Edie boxes need h_t_s > 0 and h_x_m > 0")
    if until <= since:
        raise ValueError("until must be after since")
    return _frame(
        connection,
        "SELECT * FROM analytics.edie_field(:since, :until, :h_t_s, :h_x_m)"
        " ORDER BY corridor_id, t_start, x_start_m",
        {"since": since, "until": until, "h_t_s": h_t_s, "h_x_m": h_x_m},
    )


def _frame(connection: Connection, sql: str, params: dict[str, Any]) -> pd.DataFrame:
    result = connection.execute(text(sql), params)
    return pd.DataFrame(result.fetchall(), columns=list(result.keys()))


def export_csv(
    connection: Connection,
    name: str,
    out: IO[str],
    *,
    since: datetime | date | None = None,
    until: datetime | date | None = None,
    vehicle_id: str | None = None,
) -> int:
    """Write a view as CSV (header, ISO 8601 times) to `out`; returns the number of rows."""
    frame = read_view(connection, name, since=since, until=until, vehicle_id=vehicle_id)
    frame.to_csv(out, index=False, date_format="%Y-%m-%dT%H:%M:%S.%f%z")
    return len(frame)
