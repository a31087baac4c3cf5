"""A deadline on every API request: a hung database answers 503 + Retry-After, not a hang.

PostgreSQL's statement timeout is enforced by the server, so a server that is frozen (SIGSTOP,
a stalled disk, a network black hole) never enforces it, and a request waiting on it would
wait as long as the freeze lasts. Cars and feeds retry a 503 (their pings stay spooled), so an
API request that has not started its answer `deadline_s` after its body arrived is answered
503 with Retry-After; its handler is cancelled and its late result dropped. A 503 is never an
acknowledgement, so nothing acknowledged can be lost by it: a ping committed after its request
gave up is stored, and the car's resend is a duplicate.

The clock starts when the request's body has been received (a slow upload is not the
database's wait) or at once for a request without a body.
"""

from __future__ import annotations

import asyncio
import logging
import time

import orjson
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.core.errors import RETRY_AFTER_S
from app.core.logs import RepeatedMessages
from contract.errors import DATABASE_UNAVAILABLE

log = logging.getLogger(__name__)
log.addFilter(RepeatedMessages())

# Machine clients that retry a 503 on their own; the dashboard's pages are not bounded here.
DEADLINE_PREFIXES = ("/api/", "/readyz")


class RequestDeadline:
    """ASGI middleware answering 503 to an API request not answered within `deadline_s`."""

    def __init__(self, app: ASGIApp, deadline_s: float) -> None:
        self.app = app
        self.deadline_s = deadline_s

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if (
            scope["type"] != "http"
            or self.deadline_s <= 0
            or not scope["path"].startswith(DEADLINE_PREFIXES)
        ):
            await self.app(scope, receive, send)
            return
        clock_from = time.monotonic()
        started = False  # the answer has begun: it is the handler's to finish
        gave_up = False

        async def timed_receive() -> Message:
            nonlocal clock_from
            message = await receive()
            if message["type"] == "http.request" and not message.get("more_body", False):
                clock_from = time.monotonic()
            return message

        async def guarded_send(message: Message) -> None:
            nonlocal started
            if gave_up:
                return
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        async def handle() -> None:
            await self.app(scope, timed_receive, guarded_send)

        handler = asyncio.create_task(handle())
        while True:
            remaining = clock_from + self.deadline_s - time.monotonic()
            done, _ = await asyncio.wait({handler}, timeout=max(remaining, 0.0))
            if done:
                handler.result()  # the handler's own errors propagate as they would
                return
            if started:  # the answer is streaming: let it finish
                await handler
                return
            if time.monotonic() >= clock_from + self.deadline_s:
                break
        gave_up = True
        handler.cancel()
        # The cancelled handler finishes (and returns its connection) in the background.
        handler.add_done_callback(_drop_late_outcome)
        log.warning(
            "%s %s not answered within %.1f s (database hung?): answered 503",
            scope["method"],
            _route_of(scope),
            self.deadline_s,
        )
        body = orjson.dumps(
            {"detail": "database not answering in time, retry later", "code": DATABASE_UNAVAILABLE}
        )
        await send(
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
        await send({"type": "http.response.body", "body": body})


def _route_of(scope: Scope) -> str:
    route = scope.get("route")
    path = getattr(route, "path", None)
    return path if isinstance(path, str) else "(unrouted)"


def _drop_late_outcome(task: asyncio.Task[None]) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.debug("late outcome of an abandoned request: %r", task.exception())
