"""The analytics page's pings per hour, read from the warehouse (dashboards/pages.py)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Sequence
from datetime import UTC, datetime, timedelta

from sqlalchemy import Engine, RowMapping
from sqlalchemy.ext.asyncio import async_sessionmaker

from app.core.db import make_async_engine
from dashboards import data
from dashboards.pages import pings_per_hour
from tests.planner.facts import pings

# The view divides the hour in progress by at least a minute; past two, a car pinging once a
# second reads within a few seconds' worth of its rate.
SETTLED_S = 120.0


def test_the_hour_in_progress_is_plotted_at_its_rate_not_as_a_dip(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """The chart plotted each hour's count, so the hour still running always ended it in a
    dip (half of a steady fleet's pings at half past) that read as the fleet going quiet."""
    now = datetime.now(UTC)
    hour = now.replace(minute=0, second=0, microsecond=0)
    if (now - hour).total_seconds() < SETTLED_S:
        time.sleep(SETTLED_S - (now - hour).total_seconds())
        now = datetime.now(UTC)
    # One car pinging once a second for the whole hour before and this hour up to now.
    pings(seeded_engine, "SF-001", hour - timedelta(seconds=1), [3000.0] * 3600, 25.0)
    so_far = int((now - hour).total_seconds())
    pings(seeded_engine, "SF-001", hour + timedelta(seconds=so_far - 1), [3000.0] * so_far, 25.0)

    async def read() -> Sequence[RowMapping]:
        engine = make_async_engine(seeded_database_url, pool_size=1)
        try:
            async with async_sessionmaker(engine)() as session:
                return await data.fleet_pings_hourly(session, hour - timedelta(hours=1))
        finally:
            await engine.dispose()

    rows = asyncio.run(read())
    assert [(row["hour"], row["pings"]) for row in rows] == [
        (hour - timedelta(hours=1), 3600),
        (hour, so_far),
    ]
    whole, current = pings_per_hour(rows)
    assert whole == 3600.0  # an hour that is over keeps its count
    assert 0.97 * 3600.0 <= current <= 3600.0, (so_far, current)
