"""The ingest's fleet directory: cached, reloaded ahead of its expiry without holding requests."""

from __future__ import annotations

import asyncio

from sqlalchemy import Engine, text

from app.core.db import make_async_engine
from app.ingest.directory import FleetDirectory, FleetDirectoryCache


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_a_directory_near_its_expiry_is_reloaded_in_the_background(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    clock = Clock()

    async def scenario() -> tuple[bool, bool, bool, bool]:
        engine = make_async_engine(seeded_database_url)
        release = asyncio.Event()
        try:
            cache = FleetDirectoryCache(engine, ttl_s=30, clock=clock)
            first = await cache.directory()
            with seeded_engine.begin() as connection:
                connection.execute(text("DELETE FROM dim_vehicle WHERE vehicle_id = 'SF-100'"))
            original = cache._load

            async def held() -> FleetDirectory:
                await release.wait()
                return await original()

            cache._load = held  # type: ignore[method-assign]
            clock.now = 10.0  # early in its life: the snapshot, no reload
            quiet = await cache.directory() is first and cache._refresh is None
            clock.now = 25.0  # in the last 20 %: the snapshot at once, a reload begins
            at_once = await asyncio.wait_for(cache.directory(), 1) is first
            reloading = cache._refresh is not None
            release.set()
            while cache._refresh is not None:
                await asyncio.sleep(0.01)
            clock.now = 26.0
            fresh = await cache.directory()
            return quiet, at_once, reloading, fresh.corridor_of("SF-100") is None
        finally:
            await engine.dispose()

    assert asyncio.run(scenario()) == (True, True, True, True)
