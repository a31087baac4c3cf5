"""Who a bearer token belongs to, looked up by its SHA-256 and cached for a few seconds.

Tokens are 256-bit random strings stored as sha256 hex (app.core.security), so the lookup is by
the hash of what the client presented. The cache is keyed by that hash too: an attacker cannot
steer the hash's bytes, so neither the index lookup nor the dict lookup leaks anything about a
stored token through timing; the stored hash is still compared with `hmac.compare_digest`.

Revocation: setting `api_token.revoked_at` takes effect in every server process within
`token_cache_ttl_s` (default 5 s), the life of a cache entry; unknown tokens are cached as
refused for the same time, so guessing costs no database round trip per request.

An entry in use is looked up again in the background during the last `REFRESH_AHEAD_SHARE` of
its life, so a car's requests never wait for their token's lookup (a wait that every car met
every few seconds, and that held every in-flight request of a shared token at once); an entry
is never used past its life, so revocation still takes effect within the TTL.
"""

from __future__ import annotations

import asyncio
import functools
import hmac
import time
from collections.abc import Callable
from dataclasses import dataclass

from sqlalchemy import text
from sqlalchemy.ext.asyncio import AsyncEngine
from starlette.datastructures import State

from app.core.config import Settings
from app.core.errors import is_database_outage
from app.core.ratelimit import RateLimiter
from app.core.security import TokenRole, hash_token

# Looks a token up and notes its use at most once a minute (not on every ping).
LOOKUP_SQL = text(
    """
    WITH found AS (
        SELECT token_id, kind, role, vehicle_id, token_hash
        FROM api_token
        WHERE token_hash = :token_hash AND revoked_at IS NULL
    ), touched AS (
        UPDATE api_token SET last_used_at = now()
        WHERE token_id IN (SELECT token_id FROM found)
          AND (last_used_at IS NULL OR last_used_at < now() - interval '60 seconds')
    )
    SELECT token_id, kind, role, vehicle_id, token_hash FROM found
    """
)

# Bounds the memory a flood of random tokens can take; the cache is simply emptied when full.
MAX_CACHED_TOKENS = 10_000
# The last share of an entry's life in which a request using it starts its background lookup.
REFRESH_AHEAD_SHARE = 0.4
# While its lookup fails for want of the database, a token whose entry expired less than this
# long ago (s) still stands: an outage of a few minutes must not lock the fleet out of the plans
# the server holds in memory. An older entry is no answer: a token revoked since would pass.
OUTAGE_GRACE_S = 300.0


@dataclass(frozen=True, slots=True)
class Principal:
    """The holder of a valid token: its role and, for a vehicle token, its vehicle."""

    token_id: int
    role: TokenRole
    vehicle_id: str | None

    @property
    def token_words(self) -> str:
        """The token in an error's words: "an operator token", "a vehicle token"."""
        article = "an" if self.role[0] in "aeiou" else "a"
        return f"{article} {self.role} token"

    def may_report_for(self, vehicle_id: str) -> bool:
        """A vehicle token reports only for its own vehicle; operators and admins for any."""
        if self.role == "vehicle":
            return self.vehicle_id == vehicle_id
        return self.role in ("operator", "admin")


class LookupAbandoned(ConnectionError):
    """A shared token lookup whose database query was abandoned (answered 503)."""


class TokenCache:
    """Token hash -> principal (or refusal), each entry kept `ttl_s` seconds."""

    def __init__(
        self,
        engine: AsyncEngine,
        ttl_s: float,
        *,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._engine = engine
        self._ttl_s = ttl_s
        self._clock = clock
        self._entries: dict[str, tuple[float, Principal | None]] = {}
        self._pending: dict[str, asyncio.Future[Principal | None]] = {}
        self._refreshes: set[asyncio.Task[Principal | None]] = set()

    async def principal(self, token: str) -> Principal | None:
        """The principal of a presented token, or None if it is unknown or revoked."""
        token_hash = hash_token(token)
        entry = self._entries.get(token_hash)
        now = self._clock()
        if entry is not None and entry[0] > now:
            if entry[0] - now < self._ttl_s * REFRESH_AHEAD_SHARE:
                self._refresh_in_background(token_hash, entry)
            return entry[1]
        pending = self._pending.get(token_hash)
        if pending is not None:
            return await asyncio.shield(pending)
        return await self._look_up_and_keep(token_hash, entry, self._claim(token_hash))

    async def close(self, timeout_s: float) -> None:
        """Give the background look-ups up to `timeout_s` to finish (at shutdown, before the
        engine is disposed: a look-up dropped mid-query would leave its connection to the
        garbage collector). Not longer: a frozen database must not hold the shutdown."""
        if self._refreshes:
            await asyncio.wait(set(self._refreshes), timeout=timeout_s)

    def _claim(self, token_hash: str) -> asyncio.Future[Principal | None]:
        """The answer of the one lookup of this token now starting, registered at once.

        Registered by whoever decides to look up, before the lookup's task first runs: two
        requests meeting the refresh window in one tick would otherwise both start a lookup,
        and the first to finish would unregister the second's answer, leaving whoever waited
        on it waiting for good."""
        future: asyncio.Future[Principal | None] = asyncio.get_running_loop().create_future()
        self._pending[token_hash] = future
        return future

    def _refresh_in_background(
        self, token_hash: str, entry: tuple[float, Principal | None]
    ) -> None:
        if token_hash in self._pending:
            return
        future = self._claim(token_hash)
        task = asyncio.create_task(self._look_up_and_keep(token_hash, entry, future))
        self._refreshes.add(task)
        task.add_done_callback(functools.partial(self._refresh_done, token_hash, future))

    def _refresh_done(
        self,
        token_hash: str,
        future: asyncio.Future[Principal | None],
        task: asyncio.Task[Principal | None],
    ) -> None:
        self._refreshes.discard(task)
        if not future.done():
            # Cancelled before it began (the loop shutting down): its claim is released, and
            # whoever waits on it learns the lookup was abandoned.
            del self._pending[token_hash]
            future.set_exception(LookupAbandoned("the token lookup was abandoned unanswered"))
            future.exception()
        if not task.cancelled():
            # A failed refresh changes nothing: the entry lives out its TTL, and the first
            # request after that looks the token up itself (and meets the error).
            task.exception()

    async def _look_up_and_keep(
        self,
        token_hash: str,
        entry: tuple[float, Principal | None] | None,
        future: asyncio.Future[Principal | None],
    ) -> Principal | None:
        try:
            found = await self._lookup(token_hash)
        except asyncio.CancelledError:
            # The request that looked the token up gave up (its deadline passed: a hung
            # database). The others waiting on the same lookup are not cancelled: they learn
            # the database did not answer, which is a 503 for them too.
            future.set_exception(LookupAbandoned("the token lookup was abandoned unanswered"))
            future.exception()
            raise
        except Exception as error:
            if (
                is_database_outage(error)
                and entry is not None
                and entry[1] is not None
                and self._clock() < entry[0] + OUTAGE_GRACE_S
            ):
                # the database is away: a token known a few minutes ago still is; what it may
                # do is checked as always. An older entry is no answer (OUTAGE_GRACE_S): a token
                # revoked hours ago was honoured whenever its lookup met a lock or a timeout,
                # while pings were still stored by the writer's connections
                future.set_result(entry[1])
                return entry[1]
            future.set_exception(error)
            future.exception()  # marks it retrieved when nobody else waits on it
            raise
        finally:
            del self._pending[token_hash]
        future.set_result(found)
        if len(self._entries) >= MAX_CACHED_TOKENS:
            self._make_room()
        self._entries[token_hash] = (self._clock() + self._ttl_s, found)
        return found

    def _make_room(self) -> None:
        """Drop the refused tokens' entries, and everything only if the cache is still full:
        clearing it whole, 10,000 made-up tokens (a 401 each, unthrottled) sent every car's
        next request to the database."""
        for refused in [key for key, (_, found) in self._entries.items() if found is None]:
            del self._entries[refused]
        if len(self._entries) >= MAX_CACHED_TOKENS:
            self._entries.clear()

    async def _lookup(self, token_hash: str) -> Principal | None:
        async with self._engine.begin() as connection:
            row = (await connection.execute(LOOKUP_SQL, {"token_hash": token_hash})).first()
        if row is None or not hmac.compare_digest(row.token_hash, token_hash):
            return None
        role: TokenRole = row.kind if row.kind in ("vehicle", "feed") else row.role
        return Principal(token_id=int(row.token_id), role=role, vehicle_id=row.vehicle_id)


def bearer_token(authorization: str | None) -> str | None:
    """The token of an `Authorization: Bearer <token>` header value, or None."""
    if not authorization:
        return None
    scheme, _, token = authorization.partition(" ")
    token = token.strip()
    return token if scheme.lower() == "bearer" and token else None


def token_rate_limiter(state: State) -> RateLimiter:
    """The app's per-token request limiter, made on first use from its settings."""
    limiter: RateLimiter | None = getattr(state, "token_rate_limiter", None)
    if limiter is None:
        settings: Settings = state.settings
        limiter = RateLimiter(settings.rate_limit_per_token_per_s, settings.rate_limit_burst)
        state.token_rate_limiter = limiter
    return limiter


def token_cache_for(state: State) -> TokenCache:
    """The app's token cache, made on first use from its engine and settings."""
    cache: TokenCache | None = getattr(state, "token_cache", None)
    if cache is None:
        settings: Settings = state.settings
        cache = TokenCache(state.engine, settings.token_cache_ttl_s)
        state.token_cache = cache
    return cache
