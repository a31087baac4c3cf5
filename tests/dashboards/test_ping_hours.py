"""The analytics page's pings per hour, read from the warehouse (dashboards/pages/analytics.py)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Sequence
from datetime import UTC, datetime, timedelta

from sqlalchemy import Engine, RowMapping
from sqlalchemy.ext.asyncio import async_sessionmaker

from app.core.db import make_async_engine
from dashboards import data
from dashboards.pages.analytics import pings_per_hour
from tests.planner.facts import pings

# The view divides the hour in progress by the seconds it has run, and by at least a minute
# (migration 0011).
MIN_DIVISOR_S = 60.0


def test_the_hour_in_progress_is_plotted_at_its_rate_not_as_a_dip(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """The chart plotted each hour's count, so the hour still running always ended it in a
    dip (half of a steady fleet's pings at half past) that read as the fleet going quiet."""
    now = datetime.now(UTC)
    if now.minute == 59 and now.second >= 40:  # the hour would turn while the test runs
        time.sleep(61 - now.second)
        now = datetime.now(UTC)
    hour = now.replace(minute=0, second=0, microsecond=0)
    # One car pinging once a second for the whole hour before and this hour up to now.
    pings(seeded_engine, "SF-001", hour - timedelta(seconds=1), [3000.0] * 3600, 25.0)
    so_far = max(1, int((now - hour).total_seconds()))
    pings(seeded_engine, "SF-001", hour + timedelta(seconds=so_far - 1), [3000.0] * so_far, 25.0)

    async def read() -> Sequence[RowMapping]:
        engine = make_async_engine(seeded_database_url, pool_size=1)
        try:
            async with async_sessionmaker(engine)() as session:
                return await data.fleet_pings_hourly(session, hour - timedelta(hours=1))
        finally:
            await engine.dispose()

    rows = asyncio.run(read())
    read_after_s = (datetime.now(UTC) - hour).total_seconds()
    assert [(row["hour"], row["pings"]) for row in rows] == [
        (hour - timedelta(hours=1), 3600),
        (hour, so_far),
    ]
    whole, current = pings_per_hour(rows)
    assert whole == 3600.0  # an hour that is over keeps its count
    # the pings so far over the seconds run when the view read them (between the last ping
    # and the read's end), at least a minute: 3,600 an hour once a minute has run, whatever
    # the minute; the count alone (so_far) is below that until the hour's last seconds
    lowest = 3600.0 * so_far / max(read_after_s, MIN_DIVISOR_S)
    highest = 3600.0 * so_far / max(so_far, MIN_DIVISOR_S)
    assert lowest - 1e-6 <= current <= highest + 1e-6, (so_far, read_after_s, current)
