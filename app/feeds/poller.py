"""Poll the INRIX provider every period, retrying failures with exponential backoff.

The key travels in the Authorization header only: it is never part of a URL, a log line or an
error message (any message that would contain it is scrubbed). A failed poll is retried after
1 s, 2 s, 4 s... (at most 30 s) until the next period begins, which starts afresh.

The provider serves the current minute only, so a response once fetched is never thrown away
for the warehouse's sake: it is recorded at once (`record`), and while the database does not
take it (`StoreFailed`) it waits in a backlog, retried with the same backoff without asking the
provider again, and stored oldest first once the database answers, whether or not the
provider answers then. Every wait is bounded: a provider that trickles its answer is given up
after `fetch_deadline_s`, a store the database never answers after `store_deadline_s` (a frozen
server never enforces its own statement timeout); such a store is cancelled and left to end on
its own, and no other store starts while it has not, so a hung database holds one connection,
not one a retry.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from collections.abc import Awaitable, Callable
from datetime import UTC, datetime

import httpx
import orjson
from pydantic import SecretStr

from app.feeds.recording import RecordedSnapshot

log = logging.getLogger(__name__)

FIRST_RETRY_S = 1.0
MAX_RETRY_S = 30.0
REQUEST_TIMEOUT_S = 20.0
# The whole request, however slowly its bytes come (REQUEST_TIMEOUT_S bounds each read).
FETCH_DEADLINE_S = 30.0
# One snapshot's store: over PostgreSQL's 30 s statement timeout, under the 60 s period.
STORE_DEADLINE_S = 40.0
# Snapshots fetched and not yet stored, at most: a day of minutes (kilobytes each for a
# corridor). Beyond it the oldest goes, with a line saying so; the recording still has it.
BACKLOG_LIMIT = 24 * 60
# A segment-speed response for a corridor is kilobytes (48 segments of the 2021 recordings); a
# region's a few megabytes. Larger is a provider or proxy gone wrong: read whole, a 200 MB body
# took the poller to 3 GB, on a host it shares with PostgreSQL (ops audit).
MAX_RESPONSE_BYTES = 32 * 1024 * 1024


class PollFailed(Exception):
    """One poll did not yield a usable response; the message is safe to log.

    `wait_s`: the provider asked to be left alone this long (429 or 503 with Retry-After);
    `final_this_period`: asking again within the period would get the same answer (a 4xx but
    408 and 429: a key refused, a wrong URL), so the next request waits for the next period."""

    def __init__(
        self, message: str, *, wait_s: float | None = None, final_this_period: bool = False
    ) -> None:
        super().__init__(message)
        self.wait_s = wait_s
        self.final_this_period = final_this_period


# Statuses a provider answers that asking again at once may change (a timeout, a rate limit).
RETRYABLE_CLIENT_ERRORS = frozenset({408, 429})


def _provider_refusal(response: httpx.Response) -> PollFailed:
    """The PollFailed for a non-200 answer, carrying what it says about asking again."""
    status = response.status_code
    wait_s: float | None = None
    if status in (429, 503):
        try:
            wait_s = max(float(response.headers.get("Retry-After", "")), 0.0)
        except ValueError:  # absent, or an HTTP date: the doubling back-off stands
            wait_s = None
    return PollFailed(
        f"provider answered HTTP {status}"
        + (f", asking to wait {wait_s:.0f} s" if wait_s is not None else ""),
        wait_s=wait_s,
        final_this_period=400 <= status < 500 and status not in RETRYABLE_CLIENT_ERRORS,
    )


class StoreFailed(Exception):
    """The warehouse did not take a snapshot (the database down or not answering): the
    snapshot is kept and stored again later. The message is safe to log."""


class InrixPoller:
    """Fetches the provider's segment-speed response on a fixed period."""

    def __init__(
        self,
        url: str,
        key: SecretStr,
        *,
        period_s: float,
        client: httpx.AsyncClient,
        first_retry_s: float = FIRST_RETRY_S,
        max_retry_s: float = MAX_RETRY_S,
        max_response_bytes: int = MAX_RESPONSE_BYTES,
        fetch_deadline_s: float = FETCH_DEADLINE_S,
        store_deadline_s: float = STORE_DEADLINE_S,
        backlog_limit: int = BACKLOG_LIMIT,
        sleep: Callable[[float], Awaitable[None]] = asyncio.sleep,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._url = url
        self._key = key
        self._period_s = period_s
        self._client = client
        self._first_retry_s = first_retry_s
        self._max_retry_s = max_retry_s
        self._max_response_bytes = max_response_bytes
        self._fetch_deadline_s = fetch_deadline_s
        self._store_deadline_s = store_deadline_s
        self._sleep = sleep
        self._clock = clock
        self.backlog: deque[RecordedSnapshot] = deque()
        self._backlog_limit = backlog_limit
        # a store given up on that has not ended yet (see the module docstring)
        self._abandoned_store: asyncio.Task[None] | None = None

    def _scrub(self, message: str) -> str:
        secret = self._key.get_secret_value()
        return message.replace(secret, "***") if secret else message

    async def fetch(self) -> RecordedSnapshot:
        """One request to the provider; PollFailed with a loggable reason on any failure."""
        headers = {
            "Authorization": f"Bearer {self._key.get_secret_value()}",
            "Accept": "application/json",
        }
        try:
            async with self._client.stream(
                "GET", self._url, headers=headers, timeout=REQUEST_TIMEOUT_S
            ) as response:
                if response.status_code != 200:
                    raise _provider_refusal(response)
                content = await self._read_capped(response)
        except httpx.HTTPError as error:
            reason = str(error) or type(error).__name__
            raise PollFailed(self._scrub(f"provider unreachable: {reason}")) from None
        try:
            document = orjson.loads(content)
        except orjson.JSONDecodeError:
            raise PollFailed("provider answered something that is not JSON") from None
        if not isinstance(document, dict):
            raise PollFailed("provider answered JSON that is not an object")
        return RecordedSnapshot(datetime.now(UTC), document)

    async def _read_capped(self, response: httpx.Response) -> bytes:
        """The body, or PollFailed as soon as it is known to exceed the cap (its announced
        length, or the bytes read so far): never more than the cap is held."""
        limit = self._max_response_bytes
        too_large = PollFailed(
            f"provider answered more than {limit:,} bytes: not read (a corridor's response is "
            "kilobytes)"
        )
        announced = response.headers.get("Content-Length", "")
        if announced.isdigit() and int(announced) > limit:
            raise too_large
        body = bytearray()
        async for chunk in response.aiter_bytes():
            body += chunk
            if len(body) > limit:
                raise too_large
        return bytes(body)

    async def run(
        self,
        store: Callable[[RecordedSnapshot], Awaitable[None]],
        *,
        record: Callable[[RecordedSnapshot], None] | None = None,
        count: int | None = None,
    ) -> int:
        """Poll until `count` snapshots were stored (forever if None); returns how many.

        Each period fetches one response (retried on PollFailed, from the fetch or from `store`
        finding it unusable), hands it to `record` at once, and stores the backlog oldest first,
        all of it: minutes fetched while the database was away are stored though that passes
        `count` (stopping at `count` left them fetched and never stored).
        """
        stored = 0
        next_poll = self._clock()
        # the provider's Retry-After: no request before this (the poller's clock)
        quiet_until = next_poll
        while count is None or stored < count:
            period_ends = next_poll + self._period_s
            delay = self._first_retry_s
            fetched = False
            while True:
                failures: list[str] = []
                if not fetched and self._clock() >= quiet_until:
                    try:
                        self._keep(await self._fetch_within_deadline(), record)
                        fetched = True
                    except PollFailed as error:
                        failures.append(f"INRIX poll failed: {error}")
                        if error.wait_s is not None:
                            quiet_until = self._clock() + error.wait_s
                            delay = max(delay, error.wait_s)
                        if error.final_this_period:
                            fetched = True  # no second request this period: the same answer
                # the backlog is stored whether or not this period's fetch succeeded: minutes
                # kept while the database was down need the database, not the provider
                try:
                    while self.backlog:
                        try:
                            await self._store_within_deadline(store, self.backlog[0])
                        except PollFailed:  # not a usable response: dropped
                            self.backlog.popleft()
                            # the backlog's newest is this period's: gone, ask again
                            fetched = fetched and bool(self.backlog)
                            raise
                        self.backlog.popleft()
                        stored += 1
                except PollFailed as error:
                    failures.append(f"INRIX poll failed: {error}")
                except StoreFailed as error:
                    failures.append(
                        f"INRIX snapshot not stored: {error} ({len(self.backlog)} kept to store)"
                    )
                if not failures or (count is not None and stored >= count):
                    break
                failure = "; ".join(failures)
                if self._clock() + delay >= period_ends:
                    log.warning("%s; next poll at the next period", failure)
                    break
                log.warning("%s; retrying in %.0f s", failure, delay)
                await self._sleep(delay)
                delay = min(delay * 2, self._max_retry_s)
            if count is not None and stored >= count:
                break
            # a period overrun (a slow provider, a slow store) skips the periods it covered
            # rather than polling back to back to catch up; a Retry-After pushes it further
            next_poll = max(period_ends, self._clock(), quiet_until)
            await self._sleep(max(0.0, next_poll - self._clock()))
        return stored

    def _keep(
        self, snapshot: RecordedSnapshot, record: Callable[[RecordedSnapshot], None] | None
    ) -> None:
        """Record a fetched response and put it in the backlog (its oldest dropped when full)."""
        if record is not None:
            record(snapshot)
        if len(self.backlog) >= self._backlog_limit:
            dropped = self.backlog.popleft()
            log.error(
                "INRIX backlog full (%d snapshots not stored): dropped the one fetched at %s",
                self._backlog_limit,
                dropped.recorded_at.isoformat(),
            )
        self.backlog.append(snapshot)

    async def _fetch_within_deadline(self) -> RecordedSnapshot:
        try:
            return await asyncio.wait_for(self.fetch(), self._fetch_deadline_s)
        except TimeoutError:
            raise PollFailed(
                f"provider did not answer within {self._fetch_deadline_s:g} s"
            ) from None

    async def _store_within_deadline(
        self, store: Callable[[RecordedSnapshot], Awaitable[None]], snapshot: RecordedSnapshot
    ) -> None:
        """`store(snapshot)`, StoreFailed when it has not ended within the deadline (it is
        cancelled, not awaited: its clean-up may wait on the same hung server)."""
        if self._abandoned_store is not None and not self._abandoned_store.done():
            raise StoreFailed("the database has not ended the store given up on before")
        task = asyncio.ensure_future(store(snapshot))
        done, _ = await asyncio.wait({task}, timeout=self._store_deadline_s)
        if not done:
            task.cancel()
            task.add_done_callback(_consume_outcome)
            self._abandoned_store = task
            raise StoreFailed(f"the database did not answer within {self._store_deadline_s:g} s")
        task.result()


def _consume_outcome(task: asyncio.Task[None]) -> None:
    """Read an abandoned store's outcome, so asyncio does not report it as never retrieved
    (a late success is stored: the backlog's next store of it counts a duplicate)."""
    if not task.cancelled():
        task.exception()
