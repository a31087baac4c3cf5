"""The time-space page's fleet trajectories, read from the warehouse (dashboards/data.py)."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime, timedelta

import numpy as np
from sqlalchemy import Engine
from sqlalchemy.ext.asyncio import async_sessionmaker

from app.core.db import make_async_engine
from contract.units import METRES_PER_MILE
from dashboards import data
from dashboards.figures import Trajectory
from tests.planner.facts import pings


def test_a_car_is_drawn_where_it_was_at_the_time_it_is_drawn(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """Each point took the bucket's start time and its last ping's position: at a day's view
    (120 s buckets) a car at 25 m/s was drawn 3 km ahead of where it was at that time."""
    end = datetime.now(UTC).replace(microsecond=0)
    positions = 1000.0 + 25.0 * np.arange(600)  # ten minutes at 25 m/s, one ping a second
    pings(seeded_engine, "SF-001", end, list(positions), 25.0, lane=1)
    start = end - timedelta(seconds=599)

    async def read() -> tuple[float, list[Trajectory]]:
        engine = make_async_engine(seeded_database_url, pool_size=1)
        try:
            async with async_sessionmaker(engine)() as session:
                (corridor,) = await data.corridors(session)  # the seed's one, SF-001's
                since = end - timedelta(hours=1)
                drawn = await data.fleet_trajectories(session, corridor, since, end, 120.0)
                return corridor.postmile_at_start, drawn
        finally:
            await engine.dispose()

    postmile_at_start, (path,) = asyncio.run(read())
    assert len(path.times_s) >= 5
    x_m = (path.postmiles - postmile_at_start) * METRES_PER_MILE
    np.testing.assert_allclose(x_m, 1000.0 + 25.0 * (path.times_s - start.timestamp()), atol=0.01)
