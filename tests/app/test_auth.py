"""Bearer tokens: hashed lookups, a short cache, and how fast a revocation takes effect."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime

import pytest
from sqlalchemy import Engine, text

from app.auth import Principal, TokenCache
from app.auth import tokens as tokens_module
from app.auth.tokens import OUTAGE_GRACE_S, LookupAbandoned
from app.core.db import make_async_engine
from tests.support.api import ping, serving
from tests.support.tokens import bearer, issue


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def revoke(engine: Engine) -> None:
    with engine.begin() as connection:
        connection.execute(text("UPDATE api_token SET revoked_at = now()"))


def test_tokens_resolve_to_their_role_and_vehicle(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    tokens = {
        "vehicle": issue(seeded_engine, "vehicle", "SF-003"),
        "feed": issue(seeded_engine, "feed"),
        "operator": issue(seeded_engine, "operator"),
    }

    async def resolve() -> dict[str, Principal | None]:
        engine = make_async_engine(seeded_database_url)
        try:
            cache = TokenCache(engine, ttl_s=5)
            found = {role: await cache.principal(token) for role, token in tokens.items()}
            found["unknown"] = await cache.principal("sf_unknown")
            return found
        finally:
            await engine.dispose()

    found = asyncio.run(resolve())
    assert found["vehicle"] is not None
    assert (found["vehicle"].role, found["vehicle"].vehicle_id) == ("vehicle", "SF-003")
    assert found["feed"] is not None
    assert (found["feed"].role, found["feed"].vehicle_id) == ("feed", None)
    assert found["operator"] is not None
    assert found["operator"].role == "operator"
    assert found["unknown"] is None
    with seeded_engine.connect() as connection:
        used = connection.execute(text("SELECT last_used_at FROM api_token")).scalars().all()
    assert all(moment is not None and moment <= datetime.now(UTC) for moment in used)


def test_a_revoked_token_is_refused_once_its_cache_entry_expires(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    token = issue(seeded_engine, "vehicle", "SF-001")
    clock = Clock()

    async def scenario() -> list[bool]:
        engine = make_async_engine(seeded_database_url)
        cache = TokenCache(engine, ttl_s=5, clock=clock)
        try:
            seen = [await cache.principal(token) is not None]
            revoke(seeded_engine)
            clock.now = 4.9  # within the cache's life: still honoured (and refreshed behind)
            seen.append(await cache.principal(token) is not None)
            clock.now = 5.1  # looked up again: refused
            seen.append(await cache.principal(token) is not None)
            return seen
        finally:
            # as the app's shutdown does: the background refresh started at 4.9 returns its
            # connection before the pool goes (else a later test meets it in the collector)
            await cache.close(timeout_s=5.0)
            await engine.dispose()

    assert asyncio.run(scenario()) == [True, True, False]


def test_made_up_tokens_filling_the_cache_do_not_push_out_the_fleets(
    seeded_database_url: str, seeded_engine: Engine, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A full cache was cleared whole: made-up tokens (a 401 each) flushed every car's entry,
    and the fleet's next requests all went to the database. Refused entries go first now; the
    car's token, revoked meanwhile, is still answered from its entry (no lookup)."""
    monkeypatch.setattr(tokens_module, "MAX_CACHED_TOKENS", 20)
    token = issue(seeded_engine, "vehicle", "SF-001")

    async def scenario() -> bool:
        engine = make_async_engine(seeded_database_url)
        cache = TokenCache(engine, ttl_s=60)
        try:
            assert await cache.principal(token) is not None
            revoke(seeded_engine)
            for made_up in range(40):
                assert await cache.principal(f"sf_made_up_{made_up}") is None
            return await cache.principal(token) is not None
        finally:
            await cache.close(timeout_s=5.0)
            await engine.dispose()

    assert asyncio.run(scenario())


def test_a_token_known_long_ago_is_no_answer_when_its_lookup_fails(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """When the lookup meets a lock or a timeout, a token known minutes ago is honoured (an
    outage must not lock the fleet out); one known hours ago was too, so a token revoked since
    passed, its pings stored by the writer's own connections. Past OUTAGE_GRACE_S beyond its
    entry's expiry, the error stands (a 503)."""
    token = issue(seeded_engine, "vehicle", "SF-001")
    clock = Clock()

    async def scenario() -> tuple[bool, str]:
        engine = make_async_engine(seeded_database_url, statement_timeout_s=1.0)
        cache = TokenCache(engine, ttl_s=5, clock=clock)
        try:
            await cache.principal(token)
            revoke(seeded_engine)
            with seeded_engine.begin() as locker:
                locker.execute(text("LOCK TABLE api_token IN ACCESS EXCLUSIVE MODE"))
                clock.now = 5.0 + OUTAGE_GRACE_S - 1.0  # still a token known minutes ago
                recent = await cache.principal(token) is not None
                clock.now = 5.0 + OUTAGE_GRACE_S + 1.0  # no answer
                try:
                    await cache.principal(token)
                except Exception as error:  # the database's own error: an outage, a 503
                    return recent, type(error).__name__
            return recent, "accepted"
        finally:
            await engine.dispose()

    recent, old = asyncio.run(scenario())
    assert recent
    assert old == "OperationalError"


def test_concurrent_first_requests_of_a_token_share_one_lookup(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    token = issue(seeded_engine, "admin")

    async def scenario() -> tuple[int, int]:
        engine = make_async_engine(seeded_database_url)
        lookups = 0
        try:
            cache = TokenCache(engine, ttl_s=5)
            original = cache._lookup

            async def counted(token_hash: str) -> Principal | None:
                nonlocal lookups
                lookups += 1
                return await original(token_hash)

            cache._lookup = counted  # type: ignore[method-assign]
            found = await asyncio.gather(*(cache.principal(token) for _ in range(50)))
            return lookups, sum(p is not None for p in found)
        finally:
            await engine.dispose()

    assert asyncio.run(scenario()) == (1, 50)


def test_with_no_cache_a_revocation_takes_effect_at_the_next_request(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    headers = bearer(issue(seeded_engine, "vehicle", "SF-001"))
    with serving(seeded_database_url, token_cache_ttl_s=0) as client:
        assert client.post("/api/v1/pings", json=ping(), headers=headers).status_code == 200
        revoke(seeded_engine)
        refused = client.post("/api/v1/pings", json=ping(), headers=headers)
    assert refused.status_code == 401
    assert refused.json() == {"detail": "invalid or revoked token"}


@pytest.mark.parametrize(
    ("path", "method"),
    [
        ("/api/v1/pings", "POST"),
        ("/api/v1/vehicles/SF-001/status", "POST"),
        ("/api/v1/vehicles/SF-001/config", "GET"),
        ("/api/v1/corridors/I-24-WB", "GET"),
        ("/api/v1/feeds/inrix", "POST"),
    ],
)
def test_every_api_path_needs_a_token(seeded_database_url: str, path: str, method: str) -> None:
    with serving(seeded_database_url) as client:
        answer = client.request(method, path, json={})
    assert answer.status_code == 401
    assert answer.headers["WWW-Authenticate"] == "Bearer"


def test_a_token_in_use_is_looked_up_again_before_its_entry_expires_without_a_wait(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """Near the end of an entry's life a request gets the entry at once and starts the lookup
    in the background; the lookup's answer (here: revoked) serves the requests after it."""
    token = issue(seeded_engine, "vehicle", "SF-001")
    clock = Clock()

    async def scenario() -> tuple[bool, bool, bool]:
        engine = make_async_engine(seeded_database_url)
        release = asyncio.Event()
        try:
            cache = TokenCache(engine, ttl_s=5, clock=clock)
            original = cache._lookup
            await cache.principal(token)  # first lookup at t = 0: entry until t = 5
            revoke(seeded_engine)

            async def held(token_hash: str) -> Principal | None:
                await release.wait()
                return await original(token_hash)

            cache._lookup = held  # type: ignore[method-assign]
            clock.now = 4.0  # in the last 40 % of the entry's life
            answered_at_once = await asyncio.wait_for(cache.principal(token), 1) is not None
            refreshing = bool(cache._refreshes)
            release.set()
            while cache._refreshes:
                await asyncio.sleep(0.01)
            clock.now = 4.5  # before the first entry would have expired
            return answered_at_once, refreshing, await cache.principal(token) is None
        finally:
            await engine.dispose()

    assert asyncio.run(scenario()) == (True, True, True)


def test_requests_in_the_refresh_window_in_one_tick_start_one_look_up_that_all_share(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """Two requests of one token meeting the refresh window before the background lookup has
    begun must not start a second one. Two concurrent lookups of a token each registered their
    own pending answer, the first to finish removed the other's, and the second then failed
    before answering: a request waiting on that answer hung for good (seen as a server that
    never shut down after a frozen database, two dashboard readers sharing one token)."""
    token = issue(seeded_engine, "operator")
    clock = Clock()

    async def scenario() -> tuple[int, bool]:
        engine = make_async_engine(seeded_database_url)
        release = asyncio.Event()
        lookups = 0
        try:
            cache = TokenCache(engine, ttl_s=5, clock=clock)
            original = cache._lookup
            await cache.principal(token)  # entry until t = 5

            async def held(token_hash: str) -> Principal | None:
                nonlocal lookups
                lookups += 1
                await release.wait()
                return await original(token_hash)

            cache._lookup = held  # type: ignore[method-assign]
            clock.now = 4.0  # in the refresh window: both answered from the entry at once
            await cache.principal(token)
            await cache.principal(token)
            await asyncio.sleep(0)  # the background lookup(s) begin and wait on the database
            clock.now = 6.0  # the entry has expired: this request waits on the lookup
            waiting = asyncio.create_task(cache.principal(token))
            await asyncio.sleep(0)
            release.set()
            answered = await asyncio.wait_for(waiting, 5) is not None
            return lookups, answered
        finally:
            await cache.close(timeout_s=1)
            await engine.dispose()

    assert asyncio.run(scenario()) == (1, True)


def test_a_background_look_up_cancelled_before_it_began_releases_its_waiters(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """A refresh cancelled before its first step (the loop shutting down) never runs its own
    cleanup: its claim is released for it, and a request waiting on it learns it was
    abandoned (a 503 for that request) instead of waiting for good."""
    token = issue(seeded_engine, "operator")
    clock = Clock()

    async def scenario() -> tuple[str, bool]:
        engine = make_async_engine(seeded_database_url)
        try:
            cache = TokenCache(engine, ttl_s=5, clock=clock)
            await cache.principal(token)
            clock.now = 4.0
            await cache.principal(token)  # claims the refresh; its task has not begun
            (refresh,) = cache._refreshes
            refresh.cancel()
            clock.now = 6.0
            try:
                await asyncio.wait_for(cache.principal(token), 5)
            except LookupAbandoned as error:
                outcome = type(error).__name__
            else:
                outcome = "answered"
            return outcome, bool(cache._pending)
        finally:
            await engine.dispose()

    assert asyncio.run(scenario()) == ("LookupAbandoned", False)


def test_shutdown_waits_for_a_background_look_up_only_so_long(seeded_database_url: str) -> None:
    """A look-up held by a frozen database must not hold the server's shutdown: close() gives
    up on it after its timeout, the look-up still pending."""

    async def scenario() -> bool:
        engine = make_async_engine(seeded_database_url)
        cache = TokenCache(engine, ttl_s=5)
        frozen = asyncio.create_task(asyncio.Event().wait())  # a query that never returns
        cache._refreshes.add(frozen)  # type: ignore[arg-type]
        try:
            await cache.close(timeout_s=0.2)
            return frozen.done()
        finally:
            frozen.cancel()
            await engine.dispose()

    assert asyncio.run(scenario()) is False
