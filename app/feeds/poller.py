"""Poll the INRIX provider every period, retrying failures with exponential backoff.

The key travels in the Authorization header only: it is never part of a URL, a log line or an
error message (any message that would contain it is scrubbed). A failed poll is retried after
1 s, 2 s, 4 s... (at most 30 s) until the next period begins, which starts afresh.
"""

from __future__ import annotations

import asyncio
import logging
import time
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
# A segment-speed response for a corridor is kilobytes (48 segments of the 2021 recordings); a
# region's a few megabytes. Larger is a provider or proxy gone wrong: read whole, a 200 MB body
# took the poller to 3 GB, on a host it shares with PostgreSQL (ops audit).
MAX_RESPONSE_BYTES = 32 * 1024 * 1024


class PollFailed(Exception):
    """One poll did not yield a usable response; the message is safe to log."""


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
        self._sleep = sleep
        self._clock = clock

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
                    raise PollFailed(f"provider answered HTTP {response.status_code}")
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
        self, handle: Callable[[RecordedSnapshot], Awaitable[None]], *, count: int | None = None
    ) -> int:
        """Poll until `count` snapshots were handled (forever if None); returns how many."""
        handled = 0
        next_poll = self._clock()
        while count is None or handled < count:
            period_ends = next_poll + self._period_s
            delay = self._first_retry_s
            while True:
                try:
                    snapshot = await self.fetch()
                    await handle(snapshot)
                except PollFailed as error:
                    if self._clock() + delay >= period_ends:
                        log.warning("INRIX poll failed: %s; next poll at the next period", error)
                        break
                    log.warning("INRIX poll failed: %s; retrying in %.0f s", error, delay)
                    await self._sleep(delay)
                    delay = min(delay * 2, self._max_retry_s)
                    continue
                handled += 1
                break
            if count is not None and handled >= count:
                break
            next_poll = period_ends
            await self._sleep(max(0.0, next_poll - self._clock()))
        return handled
