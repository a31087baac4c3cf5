"""The ingest's fleet directory: cached, reloaded ahead of its expiry without holding requests;
each ping's corridor the one its car was assigned at the ping's time."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime, timedelta

import numpy as np
from sqlalchemy import Engine, text

from app.core.db import make_async_engine
from app.ingest.directory import FleetDirectory, FleetDirectoryCache
from contract.corridor import trusted_heading
from tests.planner.facts import move_to_eastbound

RETENTION_DAYS = 90
# A car never moved to another corridor has the one it drives at any time.
NOW = datetime.now(UTC)


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


async def load_directory(database_url: str) -> FleetDirectory:
    """A directory freshly loaded from the database."""
    engine = make_async_engine(database_url)
    try:
        return await FleetDirectoryCache(
            engine, ttl_s=30, retention_days=RETENTION_DAYS
        ).directory()
    finally:
        await engine.dispose()


def count_loads(cache: FleetDirectoryCache) -> list[int]:
    """A one-item list the cache's loads from the database are counted in."""
    loads = [0]
    original = cache._load

    async def counted() -> FleetDirectory:
        loads[0] += 1
        return await original()

    cache._load = counted  # type: ignore[method-assign]
    return loads


def test_a_directory_near_its_expiry_is_reloaded_in_the_background(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    clock = Clock()

    async def scenario() -> tuple[bool, bool, bool, bool]:
        engine = make_async_engine(seeded_database_url)
        release = asyncio.Event()
        try:
            cache = FleetDirectoryCache(
                engine, ttl_s=30, retention_days=RETENTION_DAYS, clock=clock
            )
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
            return quiet, at_once, reloading, fresh.corridor_of("SF-100", NOW) is None
        finally:
            await engine.dispose()

    assert asyncio.run(scenario()) == (True, True, True, True)


def test_a_car_added_just_after_a_reload_is_known_to_its_first_ping(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """The agent drops pings the server rejects: a car added to the roster within
    MIN_RELOAD_INTERVAL_S of a reload must not be "unknown" to them. The request waits for the
    next reload instead; a stream of bad ids still costs at most one reload per interval."""

    async def scenario() -> tuple[bool, bool, int]:
        engine = make_async_engine(seeded_database_url)
        try:
            cache = FleetDirectoryCache(engine, ttl_s=30, retention_days=RETENTION_DAYS)
            loads = count_loads(cache)
            await cache.directory(["SF-NOBODY"])  # a bad id: this reload is its answer
            with seeded_engine.begin() as connection:
                connection.execute(
                    text(
                        "INSERT INTO dim_vehicle (vehicle_id, vin, make, model, year, actuation, "
                        "corridor_id, route, assigned_lane, controller_name, controller_params) "
                        "SELECT 'SF-777', 'VIN-SF-777', make, model, year, actuation, "
                        "corridor_id, route, assigned_lane, controller_name, controller_params "
                        "FROM dim_vehicle WHERE vehicle_id = 'SF-001'"
                    )
                )
            new_car = await cache.directory(["SF-777"])
            bad_ids = await asyncio.gather(*(cache.directory(["SF-NOBODY"]) for _ in range(20)))
            return (
                new_car.corridor_of("SF-777", NOW) is not None,
                all(directory.corridor_of("SF-NOBODY", NOW) is None for directory in bad_ids),
                loads[0],
            )
        finally:
            await engine.dispose()

    known, still_unknown, loads = asyncio.run(scenario())
    assert known
    assert still_unknown
    assert loads <= 3  # the bad id's, the new car's, and one for the 20 bad requests together


def test_a_newer_config_version_reloads_once_even_when_the_roster_stays_behind(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """A ping naming a config version newer than the snapshot's reloads it (the car was moved
    since). A version the reloaded roster is still behind (a database restored from an older
    backup) costs no further reload: it would only make every ping of that car wait."""

    async def scenario() -> tuple[int, int, int, bool]:
        engine = make_async_engine(seeded_database_url)
        try:
            cache = FleetDirectoryCache(engine, ttl_s=30, retention_days=RETENTION_DAYS)
            loads = count_loads(cache)
            first = await cache.directory(["SF-001"])
            held = first.config_versions["SF-001"]
            await cache.directory(["SF-001"], config_versions={"SF-001": held})
            same = loads[0]
            with seeded_engine.begin() as connection:
                connection.execute(
                    text(
                        "UPDATE dim_vehicle SET config_version = config_version + 1 "
                        "WHERE vehicle_id = 'SF-001'"
                    )
                )
            moved = await cache.directory(["SF-001"], config_versions={"SF-001": held + 1})
            after_move = loads[0]
            for _ in range(3):  # a version the roster never reaches
                await cache.directory(["SF-001"], config_versions={"SF-001": held + 5})
            return same, after_move, loads[0], moved.config_versions["SF-001"] == held + 1
        finally:
            await engine.dispose()

    same, after_move, loads, seen = asyncio.run(scenario())
    assert same == 1  # the version it holds: no reload
    assert after_move == 2  # a newer one: reloaded,
    assert seen  # and the move is known
    assert loads == 3  # the version ahead of the roster: one reload, then none


def test_a_lone_fix_is_placed_where_the_vectorised_match_places_it(
    seeded_database_url: str,
) -> None:
    """The writer places a small group's fixes one by one: same x_m, same off-corridor verdict
    (too far, outside the corridor's ends, driving against it), same trust in slow headings."""
    corridor = asyncio.run(load_directory(seeded_database_url)).corridor_of("SF-001", NOW)
    assert corridor is not None
    assert corridor.geometry is not None
    geometry = corridor.geometry
    rng = np.random.default_rng(7)
    x = rng.uniform(-500, geometry.length_m + 500, 400)
    lat, lon = geometry.position(np.clip(x, 0, geometry.length_m))
    lat = lat + rng.normal(0, 0.0004, len(x))  # tens of metres: some fixes off the corridor
    along = geometry.heading_deg(np.clip(x, 0, geometry.length_m))
    heading = np.where(rng.random(len(x)) < 0.3, (along + 180) % 360, along)
    speed = rng.choice([0.0, 1.5, 25.0], len(x))

    vectorised = corridor.x_m(lat, lon, trusted_heading(heading, speed))
    one_by_one = [
        corridor.x_m_of_fix(float(a), float(o), float(h), float(v))
        for a, o, h, v in zip(lat, lon, heading, speed, strict=True)
    ]

    assert [v is None for v in one_by_one] == [v is None for v in vectorised]
    assert 0 < sum(v is None for v in vectorised) < len(x)
    placed = [(a, b) for a, b in zip(one_by_one, vectorised, strict=True) if a is not None]
    assert np.allclose([a for a, _ in placed], [b for _, b in placed], atol=1e-6)


def test_a_moved_car_is_on_the_corridor_it_was_assigned_at_each_ts(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """A car's spool may hold pings from before an operator moved it to another corridor: they
    belong to the corridor it was assigned then, [valid_from, valid_to) as the views read it."""
    move_to_eastbound(seeded_engine, "SF-001")
    with seeded_engine.connect() as connection:
        moved_at = connection.execute(
            text(
                "SELECT valid_from FROM dim_vehicle_assignment "
                "WHERE vehicle_id = 'SF-001' AND valid_to = 'infinity'"
            )
        ).scalar_one()

    directory = asyncio.run(load_directory(seeded_database_url))

    def corridor_at(ts: datetime) -> str | None:
        corridor = directory.corridor_of("SF-001", ts)
        return None if corridor is None else corridor.corridor_id

    assert corridor_at(moved_at - timedelta(days=30)) == "I-24-WB"
    assert corridor_at(moved_at - timedelta(microseconds=1)) == "I-24-WB"
    assert corridor_at(moved_at) == "I-24-EB"
    assert corridor_at(moved_at + timedelta(minutes=5)) == "I-24-EB"
    assert directory.corridor_of("SF-002", moved_at - timedelta(days=30)) is not None


def test_the_directory_loads_only_corridor_changes_a_ping_in_retention_can_meet(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """Most cars have one assignment, and a change of lane or route moves no ping to another
    corridor: neither costs the directory anything. Nor does a corridor change older than the
    retention window (plus a day's margin), whose pings ingest refuses anyway."""
    move_to_eastbound(seeded_engine, "SF-001")
    with seeded_engine.begin() as connection:
        connection.execute(
            text("UPDATE dim_vehicle SET assigned_lane = 3 WHERE vehicle_id = 'SF-002'")
        )
        connection.execute(
            text("UPDATE dim_vehicle SET corridor_id = 'I-24-EB' WHERE vehicle_id = 'SF-003'")
        )
        # SF-003's move made long ago: beyond the window and its margin
        for column, which in (("valid_to", "<>"), ("valid_from", "=")):
            connection.execute(
                text(
                    f"UPDATE dim_vehicle_assignment SET {column} = now() - :age "
                    f"WHERE vehicle_id = 'SF-003' AND valid_to {which} 'infinity'"
                ),
                {"age": timedelta(days=RETENTION_DAYS + 2)},
            )

    directory = asyncio.run(load_directory(seeded_database_url))

    assert set(directory.earlier_corridors) == {"SF-001"}
    assert directory.earlier_corridors["SF-001"].corridor_ids == ("I-24-WB",)
