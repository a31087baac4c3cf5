"""A deadline on every API request: a hung database answers 503 + Retry-After, not a hang.

PostgreSQL's statement timeout is enforced by the server, so a server that is frozen (SIGSTOP,
a stalled disk, a network black hole) never enforces it, and a request waiting on it would
wait as long as the freeze lasts. An API request that has not started its answer `deadline_s`
after its body arrived asks the process's `DatabaseWatch` whether the database still answers
(one `SELECT 1` on its own connection, within `probe_timeout_s`, shared by every waiting
request). If it does, the request is merely slow (a busy machine, a big query) and waits
another `deadline_s`; if not, it is answered 503 with Retry-After, its handler cancelled and
its late result dropped. Cars and feeds retry a 503 (their pings stay spooled), and a 503 is
never an acknowledgement: a ping committed after its request gave up is stored, and the car's
resend is a duplicate.

The clock starts when the request's body has been received (a slow upload is not the
database's wait) or at once for a request without a body.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from typing import Any

import orjson
import psycopg
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.core.db import libpq_url
from app.core.errors import RETRY_AFTER_S
from app.core.logs import RepeatedMessages
from contract.errors import DATABASE_UNAVAILABLE

log = logging.getLogger(__name__)
log.addFilter(RepeatedMessages())

# How long the database has to answer `SELECT 1` before it counts as hung.
PROBE_TIMEOUT_S = 0.7
# Machine clients that retry a 503 on their own; the dashboard's pages are not bounded here.
DEADLINE_PREFIXES = ("/api/", "/readyz")


class DatabaseWatch:
    """Whether the database answers at all, probed at most once per `probe_timeout_s`."""

    def __init__(self, url: str, probe_timeout_s: float) -> None:
        self._url = libpq_url(url)
        self._timeout_s = probe_timeout_s
        self._connection: psycopg.AsyncConnection[Any] | None = None
        self._probe: asyncio.Task[bool] | None = None
        self._verdict = (-float("inf"), True)  # (when, answered)
        # Attempts given up on, and the closing of the connections they answered with late:
        # the probe owns every connection it opens until it is closed.
        self._abandoned: set[asyncio.Task[psycopg.AsyncConnection[Any]]] = set()
        self._closing: set[asyncio.Task[None]] = set()

    async def answers(self) -> bool:
        """True when a `SELECT 1` came back within the probe timeout.

        A silent database is believed silent for one probe timeout (every request waiting on
        it is answered at once); an answer is not remembered, since it says nothing of the
        moment after.
        """
        when, answered = self._verdict
        if not answered and time.monotonic() - when < self._timeout_s:
            return False
        if self._probe is None or self._probe.done():
            self._probe = asyncio.create_task(self._run_probe())
        return await asyncio.shield(self._probe)

    async def _run_probe(self) -> bool:
        # Not `asyncio.timeout` around the query: cancelling a psycopg query asks the server to
        # cancel it, which waits on the very server that does not answer. The attempt is left
        # to finish (or fail) in the background instead.
        attempt = asyncio.create_task(self._select_one(self._connection))
        done, _ = await asyncio.wait({attempt}, timeout=self._timeout_s)
        answered = bool(done) and attempt.exception() is None
        if answered:
            self._connection = attempt.result()
        else:
            self._connection = None  # closed by its attempt, or abandoned with it
            if not done:
                self._abandoned.add(attempt)
                attempt.add_done_callback(self._late_outcome)
        self._verdict = (time.monotonic(), answered)
        return answered

    async def _select_one(
        self, connection: psycopg.AsyncConnection[Any] | None
    ) -> psycopg.AsyncConnection[Any]:
        if connection is None or connection.closed:
            connection = await psycopg.AsyncConnection.connect(
                self._url, autocommit=True, connect_timeout=max(2, math.ceil(self._timeout_s))
            )
        try:
            await connection.execute("SELECT 1")
        except BaseException:
            await connection.close()
            raise
        return connection

    def _late_outcome(self, attempt: asyncio.Task[psycopg.AsyncConnection[Any]]) -> None:
        self._abandoned.discard(attempt)
        if attempt.cancelled():
            return
        if attempt.exception() is not None:
            log.debug("late outcome of an abandoned probe: %r", attempt.exception())
            return
        closing = asyncio.create_task(self._close_quietly(attempt.result()))
        self._closing.add(closing)
        closing.add_done_callback(self._closing.discard)

    async def _close_quietly(self, connection: psycopg.AsyncConnection[Any]) -> None:
        with contextlib.suppress(psycopg.Error, OSError, TimeoutError):
            async with asyncio.timeout(self._timeout_s):
                await connection.close()

    async def close(self) -> None:
        """Close every connection the probe opened (at shutdown), giving a late attempt one
        probe timeout to finish."""
        connection, self._connection = self._connection, None
        if self._abandoned:
            await asyncio.wait(set(self._abandoned), timeout=self._timeout_s)
        if connection is not None:
            await self._close_quietly(connection)
        if self._closing:
            await asyncio.wait(set(self._closing), timeout=self._timeout_s)


class RequestDeadline:
    """ASGI middleware answering 503 to an API request held by a database that does not answer.

    The handler runs in the request's own task, and one sweeper task per process looks at the
    clocks of the requests in flight every `deadline_s / 8`: a task and a wait per request cost
    ~8.5 us (bench/middleware.py), a twentieth of a ping's whole server time. Only when a
    deadline has passed does a watchdog task ask the database; if it is silent, the watchdog
    answers 503 itself and cancels the handler, so the answer leaves at once whatever the
    handler's cleanup still waits for (cancelling a psycopg query asks the frozen server).
    """

    def __init__(self, app: ASGIApp, deadline_s: float, watch: DatabaseWatch) -> None:
        self.app = app
        self.deadline_s = deadline_s
        self.watch = watch
        self._in_flight: set[_RequestClock] = set()
        self._sweeper: asyncio.Task[None] | None = None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if (
            scope["type"] != "http"
            or self.deadline_s <= 0
            or not scope["path"].startswith(DEADLINE_PREFIXES)
        ):
            await self.app(scope, receive, send)
            return
        request = _RequestClock(self, scope, receive, send)
        self._in_flight.add(request)
        sweeper = self._sweeper
        if sweeper is None or sweeper.done() or sweeper.get_loop() is not request.loop:
            self._sweeper = request.loop.create_task(self._sweep())
        try:
            await self.app(scope, request.timed_receive, request.guarded_send)
        except asyncio.CancelledError:
            if not request.gave_up or request.withdraw_cancellation():
                raise  # not the watchdog's, or someone else's too (shutdown): it stands
        except Exception as error:
            if not request.gave_up:
                raise  # the handler's own errors propagate as they would
            request.withdraw_cancellation()
            log.debug("late outcome of an abandoned request: %r", error)
        else:
            if request.gave_up:  # the handler swallowed the cancellation
                request.withdraw_cancellation()
        finally:
            self._in_flight.discard(request)
            await request.finish()

    async def _sweep(self) -> None:
        """Start a watchdog for each request past its deadline; ends when none is in flight."""
        while self._in_flight:
            await asyncio.sleep(self.deadline_s / 8)
            now = time.monotonic()
            for request in list(self._in_flight):
                request.check(now)


class _RequestClock:
    """One request's clock and, once its deadline has passed, its watchdog."""

    __slots__ = (
        "_deadline",
        "_scope",
        "_receive",
        "_send",
        "_request",
        "_watchdog",
        "loop",
        "clock_from",
        "started",
        "gave_up",
        "finished",
    )

    def __init__(
        self, deadline: RequestDeadline, scope: Scope, receive: Receive, send: Send
    ) -> None:
        self._deadline = deadline
        self._scope = scope
        self._receive = receive
        self._send = send
        self.loop = asyncio.get_running_loop()
        self._request = asyncio.current_task()
        self._watchdog: asyncio.Task[None] | None = None
        self.clock_from = time.monotonic()
        self.started = False  # the answer has begun: it is the handler's to finish
        self.gave_up = False
        self.finished = False

    async def timed_receive(self) -> Message:
        message = await self._receive()
        if message["type"] == "http.request" and not message.get("more_body", False):
            self.clock_from = time.monotonic()
        return message

    async def guarded_send(self, message: Message) -> None:
        if self.gave_up:
            return
        if message["type"] == "http.response.start":
            self.started = True
        await self._send(message)

    def check(self, now: float) -> None:
        """Past the deadline, not answering, not being asked about yet: ask the database."""
        if self.finished or self.started or self._watchdog is not None:
            return
        if now >= self.clock_from + self._deadline.deadline_s:
            self._watchdog = self.loop.create_task(self._ask_the_database())

    def withdraw_cancellation(self) -> bool:
        """Take back the watchdog's cancellation of the request's task (it has been delivered);
        True when the task was cancelled by someone else as well."""
        if self._request is None or self._request.cancelling() == 0:
            return False
        return self._request.uncancel() > 0

    async def _ask_the_database(self) -> None:
        if await self._deadline.watch.answers():
            # Merely slow (a busy machine, a big query): it gets another deadline.
            self.clock_from = time.monotonic()
            self._watchdog = None
            return
        if self.finished or self.started:
            return
        self.gave_up = True
        if self._request is not None:
            # The handler finishes (and returns its connection) in its own time; its late
            # outcome is dropped by RequestDeadline.__call__.
            self._request.cancel()
        log.warning(
            "%s %s not answered within %.1f s and the database does not answer: 503",
            self._scope["method"],
            _route_of(self._scope),
            self._deadline.deadline_s,
        )
        body = orjson.dumps(
            {"detail": "database not answering in time, retry later", "code": DATABASE_UNAVAILABLE}
        )
        await self._send(
            {
                "type": "http.response.start",
                "status": 503,
                "headers": [
                    (b"content-type", b"application/json"),
                    (b"content-length", str(len(body)).encode()),
                    (b"retry-after", str(RETRY_AFTER_S).encode()),
                ],
            }
        )
        await self._send({"type": "http.response.body", "body": body})

    async def finish(self) -> None:
        """The handler is done; after a 503, the request ends once the 503 has been sent."""
        self.finished = True
        watchdog = self._watchdog
        if watchdog is None or watchdog.done():
            return
        if self.gave_up:
            await asyncio.shield(watchdog)
        else:
            watchdog.cancel()  # asking the database about a request that no longer waits


def _route_of(scope: Scope) -> str:
    route = scope.get("route")
    path = getattr(route, "path", None)
    return path if isinstance(path, str) else "(unrouted)"
