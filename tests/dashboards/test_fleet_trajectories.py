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
from tests.planner.facts import move_to_eastbound, pings


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


def test_a_car_moved_to_another_corridor_stays_on_the_first_for_the_time_before(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """The trajectories and the engagement share read each ping on the corridor its car was
    assigned at the ping's time: moving a car does not carry its past drives along."""
    now = datetime.now(UTC).replace(microsecond=0)
    before = now - timedelta(minutes=10)
    pings(
        seeded_engine, "SF-001", before, [1000.0 + 25.0 * i for i in range(60)], 25.0, engaged=True
    )
    move_to_eastbound(seeded_engine, "SF-001")
    after = now + timedelta(minutes=2)  # its 60 pings all come after the move
    pings(
        seeded_engine, "SF-001", after, [1000.0 + 25.0 * i for i in range(60)], 25.0, engaged=False
    )
    since = now - timedelta(hours=1)

    async def read() -> dict[str, tuple[list[Trajectory], tuple[int, float | None]]]:
        engine = make_async_engine(seeded_database_url, pool_size=1)
        try:
            async with async_sessionmaker(engine)() as session:
                return {
                    corridor.corridor_id: (
                        await data.fleet_trajectories(session, corridor, since, after, 10.0),
                        await data.engagement_share(session, corridor.corridor_id, since, after),
                    )
                    for corridor in await data.corridors(session)
                }
        finally:
            await engine.dispose()

    read_back = asyncio.run(read())
    (west_path,), west_share = read_back["I-24-WB"]
    (east_path,), east_share = read_back["I-24-EB"]
    assert west_path.times_s.max() <= before.timestamp()
    assert east_path.times_s.min() > now.timestamp()
    assert (west_share, east_share) == ((60, 1.0), (60, 0.0))
