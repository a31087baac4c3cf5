"""The fleet's own side of the MOTION figure: its pings on the corridor and the day's engagement.

Read from the warehouse (`fact_vehicle_ping`, `analytics.engagement_fleet_daily_between`), the
same rows and definition as the analytics page, so the share printed on the figure is the one
`smoothfleet analytics export engagement_fleet_daily` gives.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, date, datetime, timedelta

import pandas as pd
from sqlalchemy import Connection, text

# A car's trace is broken where its pings are further apart than this (it left the corridor,
# or lost its fix): the figure does not draw a line across the gap.
TRACE_GAP_S = 5.0


@dataclass(frozen=True, slots=True)
class FleetDay:
    """The fleet's pings on a corridor in a window, and the pooled engagement share of the day."""

    pings: pd.DataFrame  # vehicle_id, ts, x_m, is_controller_engaged
    engagement_share: float | None


def fleet_pings(
    connection: Connection, corridor_id: str, since: datetime, until: datetime
) -> FleetDay:
    """The fleet's map-matched pings in [since, until) and the engagement share of since's day."""
    result = connection.execute(
        text(
            "SELECT p.vehicle_id, p.ts, p.x_m, coalesce(p.is_controller_engaged, false) AS engaged"
            # the corridor each ping's car was assigned at its ts, not the car's corridor now
            " FROM fact_vehicle_ping p JOIN dim_vehicle_assignment a ON a.vehicle_id = p.vehicle_id"
            " AND p.ts >= a.valid_from AND p.ts < a.valid_to"
            " WHERE p.ts >= :since AND p.ts < :until AND p.x_m IS NOT NULL"
            " AND a.corridor_id = :corridor ORDER BY p.vehicle_id, p.ts"
        ),
        {"since": since, "until": until, "corridor": corridor_id},
    )
    pings = pd.DataFrame(
        result.fetchall(), columns=["vehicle_id", "ts", "x_m", "is_controller_engaged"]
    )
    return FleetDay(pings=pings, engagement_share=engagement_share(connection, since.date()))


def engagement_share(connection: Connection, day: date) -> float | None:
    """The fleet's pooled engagement share of a UTC day (None without pings on the corridor)."""
    since = datetime(day.year, day.month, day.day, tzinfo=UTC)
    share = connection.execute(
        text(
            "SELECT engagement_share FROM analytics.engagement_fleet_daily_between(:since, :until)"
            " WHERE day = :day"
        ),
        {"since": since, "until": since + timedelta(days=1), "day": day},
    ).scalar_one_or_none()
    return None if share is None else float(share)
