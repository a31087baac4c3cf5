"""The feeds page's pings per minute, read from the warehouse (dashboards/data.py)."""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from datetime import UTC, datetime, timedelta

from sqlalchemy import Engine, RowMapping
from sqlalchemy.ext.asyncio import async_sessionmaker

from app.core.db import make_async_engine
from dashboards import data
from tests.planner.facts import pings


def test_the_window_s_first_minute_counts_all_of_its_pings(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """The page asks for the last hour from the second it is loaded; the first minute held only
    the pings after that second, so the chart of pings per second began with a dip every time
    (half the fleet's rate when loaded at :30) that read as a dropout an hour ago."""
    minute = datetime.now(UTC).replace(second=0, microsecond=0) - timedelta(minutes=10)
    # Three whole minutes of one car pinging once a second.
    pings(seeded_engine, "SF-001", minute + timedelta(seconds=179), [3000.0] * 180, 25.0)

    async def read() -> Sequence[RowMapping]:
        engine = make_async_engine(seeded_database_url, pool_size=1)
        try:
            async with async_sessionmaker(engine)() as session:
                return await data.pings_per_minute(session, minute + timedelta(seconds=30))
        finally:
            await engine.dispose()

    rows = asyncio.run(read())
    assert [(row["minute"], row["pings"], row["vehicles"]) for row in rows] == [
        (minute + timedelta(minutes=index), 60, 1) for index in range(3)
    ]
