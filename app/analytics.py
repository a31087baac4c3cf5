"""The analytics views (schema `analytics`, migration 0002) as pandas DataFrames, and CSV export.

The SQL is the single definition of every figure (docs/analytics.md); this module only names the
views, filters them by time or vehicle, and hands the rows to pandas. Times come back as
timezone-aware UTC timestamps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import UTC, date, datetime, timedelta
from typing import IO, Any

import pandas as pd
from sqlalchemy import Connection, text


class ViewRequestError(ValueError):
    """A request for a view that cannot be answered as asked; the message says why."""


class UnknownView(ViewRequestError):
    """The name is not one of the analytics views; the message lists the known ones."""


class NotPerVehicle(ViewRequestError):
    """A vehicle was named for a view whose rows are not per vehicle."""


class UnknownVehicle(ViewRequestError):
    """The vehicle named is not on the roster: a misspelt id would read as a car with no data."""


class EmptyWindow(ViewRequestError):
    """The window ends before it starts: reversed bounds are a mistake in the request, not a
    question whose answer is no rows. (Equal bounds are a window: a day or hour view widens it
    to the whole bucket it falls in.)"""


@dataclass(frozen=True)
class AnalyticsView:
    """A view of the analytics schema: what one row is, and its time column for --since/--until."""

    name: str
    grain: str
    time_column: str
    has_vehicle: bool
    # analytics.<function>(since, until): the view over a window, reading only its pings.
    window_function: str | None = None


VIEWS: dict[str, AnalyticsView] = {
    view.name: view
    for view in (
        AnalyticsView(
            "engagement_daily", "vehicle x UTC day", "day", True, "engagement_daily_between"
        ),
        AnalyticsView(
            "engagement_fleet_daily", "UTC day", "day", False, "engagement_fleet_daily_between"
        ),
        AnalyticsView(
            "ping_rate_hourly", "vehicle x UTC hour", "hour", True, "ping_rate_hourly_between"
        ),
        AnalyticsView("fleet_ping_hourly", "UTC hour", "hour", False, "fleet_ping_hourly_between"),
        AnalyticsView("inrix_latency", "corridor x INRIX snapshot", "measured_at", False),
        AnalyticsView("plan_adherence", "ping following a plan", "ts", True),
        AnalyticsView(
            "plan_adherence_daily", "vehicle x UTC day", "day", True, "plan_adherence_daily_between"
        ),
        AnalyticsView("edie_boxes", "corridor x 10 s x 200 m box", "t_start", False, "edie_field"),
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


def _as_utc(value: datetime | date) -> datetime:
    """The moment in UTC (naive: read as UTC), so a window cut to whole days or hours is cut
    where the views' UTC buckets begin, whatever zone the bound was written in, and a date or a
    naive bound never reaches PostgreSQL, which would read it in the session's time zone."""
    if isinstance(value, datetime):
        return value.astimezone(UTC) if value.tzinfo is not None else value.replace(tzinfo=UTC)
    return datetime(value.year, value.month, value.day, tzinfo=UTC)


def bucket_window(
    column: str, since: datetime | date | None, until: datetime | date | None
) -> tuple[datetime | str, datetime | str]:
    """The ping-time window of whole days or hours: rows with since <= bucket < until.

    A day view keeps the days that start before `until`, an hour view the hours that start
    before it: the partial last day or hour is kept whole, as the first one is. The Edie boxes
    (`t_start`) are widened to whole boxes as well: a box cut by the window would be divided by
    its whole area and read too thin. Other views take the bounds as they are.
    """
    lower: datetime | str = "-infinity"
    upper: datetime | str = "infinity"
    if since is not None:
        lower = _as_utc(since)
        if column == "day":
            lower = lower.replace(hour=0, minute=0, second=0, microsecond=0)
        elif column == "hour":
            lower = lower.replace(minute=0, second=0, microsecond=0)
        elif column == "t_start":
            lower = box_start(lower, EDIE_H_T_S)
    if until is not None:
        upper = _as_utc(until)
        if column == "day" and upper != upper.replace(hour=0, minute=0, second=0, microsecond=0):
            upper = upper.replace(hour=0, minute=0, second=0, microsecond=0) + timedelta(days=1)
        elif column == "hour" and upper != upper.replace(minute=0, second=0, microsecond=0):
            upper = upper.replace(minute=0, second=0, microsecond=0) + timedelta(hours=1)
        elif column == "t_start":
            upper = box_end(upper, EDIE_H_T_S)
    if isinstance(lower, datetime) and isinstance(upper, datetime) and upper == lower:
        # equal bounds on a bucket's start (--since 2022-11-16 --until 2022-11-16) ask for that
        # bucket, as equal bounds inside it do, not for nothing
        upper = lower + {
            "day": timedelta(days=1),
            "hour": timedelta(hours=1),
            "t_start": timedelta(seconds=EDIE_H_T_S),
        }.get(column, timedelta(0))
    return lower, upper


_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)


def box_start(moment: datetime, h_t_s: float) -> datetime:
    """The start of the h_t box holding `moment`: boxes start at multiples of h_t since the
    epoch, as `analytics.edie_field` numbers them."""
    boxes = math.floor((moment - _EPOCH).total_seconds() / h_t_s)
    return _EPOCH + timedelta(seconds=boxes * h_t_s)


def box_end(moment: datetime, h_t_s: float) -> datetime:
    """The end of the last h_t box a window ending at `moment` (excluded) touches."""
    boxes = math.ceil((moment - _EPOCH).total_seconds() / h_t_s)
    return _EPOCH + timedelta(seconds=boxes * h_t_s)


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
        raise NotPerVehicle(f"analytics view {name} has no vehicle_id column")
    if since is not None and until is not None and _as_utc(until) < _as_utc(since):
        raise EmptyWindow(
            f"the window ends before it starts: until {_as_utc(until).isoformat()} is before "
            f"since {_as_utc(since).isoformat()}"
        )
    params: dict[str, Any] = {}
    conditions: list[str] = []
    if chosen.window_function is not None and (since is not None or until is not None):
        # The view's function over the window reads only that window's pings.
        params["since"], params["until"] = bucket_window(chosen.time_column, since, until)
        source = (
            f"analytics.{chosen.window_function}"
            "(CAST(:since AS timestamptz), CAST(:until AS timestamptz))"
        )
    else:
        source = f"analytics.{name}"
        if since is not None:
            conditions.append(f"{chosen.time_column} >= :since")
            params["since"] = _as_utc(since)
        if until is not None:
            conditions.append(f"{chosen.time_column} < :until")
            params["until"] = _as_utc(until)
    if vehicle_id is not None:
        conditions.append("vehicle_id = :vehicle_id")
        params["vehicle_id"] = vehicle_id
    where = f" WHERE {' AND '.join(conditions)}" if conditions else ""
    order = f"vehicle_id, {chosen.time_column}" if chosen.has_vehicle else chosen.time_column
    if name == "inrix_latency":
        order = "corridor_id, measured_at"
    if name == "edie_boxes":
        order = "corridor_id, t_start, x_start_m"
    return f"SELECT * FROM {source}{where} ORDER BY {order}", params


def read_view(
    connection: Connection,
    name: str,
    *,
    since: datetime | date | None = None,
    until: datetime | date | None = None,
    vehicle_id: str | None = None,
) -> pd.DataFrame:
    """One analytics view as a DataFrame (optionally a time window and one vehicle, which must
    be on the roster: UnknownVehicle)."""
    sql, params = view_query(name, since=since, until=until, vehicle_id=vehicle_id)
    if (
        vehicle_id is not None
        and not connection.execute(
            text("SELECT 1 FROM dim_vehicle WHERE vehicle_id = :vehicle_id"),
            {"vehicle_id": vehicle_id},
        ).first()
    ):
        raise UnknownVehicle(f"no vehicle {vehicle_id!r} on the roster")
    return _frame(connection, sql, params)


def edie_field(
    connection: Connection,
    since: datetime,
    until: datetime,
    *,
    h_t_s: float = EDIE_H_T_S,
    h_x_m: float = EDIE_H_X_M,
) -> pd.DataFrame:
    """Edie's fields of the pings in [since, until), widened to whole h_t boxes, on
    h_t x h_x boxes (paper, Results)."""
    if h_t_s <= 0 or h_x_m <= 0:
        raise ValueError("Edie boxes need h_t_s > 0 and h_x_m > 0")
    since, until = _as_utc(since), _as_utc(until)  # a naive bound is UTC, as everywhere here
    if until <= since:
        raise ValueError("until must be after since")
    since, until = box_start(since, h_t_s), box_end(until, h_t_s)
    return _frame(
        connection,
        "SELECT * FROM analytics.edie_field(:since, :until, :h_t_s, :h_x_m)"
        " ORDER BY corridor_id, t_start, x_start_m",
        {"since": since, "until": until, "h_t_s": h_t_s, "h_x_m": h_x_m},
    )


def _frame(connection: Connection, sql: str, params: dict[str, Any]) -> pd.DataFrame:
    result = connection.execute(text(sql), params)
    return pd.DataFrame(result.fetchall(), columns=list(result.keys()))


def export_csv(frame: pd.DataFrame, out: IO[str]) -> int:
    """Write a view's rows (`read_view`) as CSV (header, ISO 8601 times) to `out`; returns the
    number of rows. The rows are read before anything is written, so a request refused or a
    query that fails leaves an earlier export where it is."""
    frame.to_csv(out, index=False, date_format="%Y-%m-%dT%H:%M:%S.%f%z")
    return len(frame)
