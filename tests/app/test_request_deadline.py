"""The request deadline: 503 at once when the database is silent, never for a merely slow one.

The handler runs in the request's own task and a sweeper watches the clocks, so these tests
call the middleware as uvicorn does, with a real database (slow request) or a listener that
accepts connections and never answers (a frozen database).
"""

from __future__ import annotations

import asyncio
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from starlette.types import Message, Receive, Scope, Send

from app.core.deadline import DatabaseWatch, RequestDeadline

DEADLINE_S = 0.3
PROBE_S = 0.2


@contextmanager
def silent_database() -> Iterator[str]:
    """A URL whose server accepts connections and never says a word."""
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(16)
    try:
        yield f"postgresql+psycopg://nobody@127.0.0.1:{listener.getsockname()[1]}/nothing"
    finally:
        listener.close()


def request_scope() -> Scope:
    return {"type": "http", "method": "POST", "path": "/api/v1/pings", "headers": []}


async def call(app: RequestDeadline) -> tuple[list[Message], float]:
    """Run one request; what was sent and when the first message left (s from the start)."""
    sent: list[Message] = []
    first_at: list[float] = []
    began = time.monotonic()

    async def receive() -> Message:
        return {"type": "http.request", "body": b"{}", "more_body": False}

    async def send(message: Message) -> None:
        if not first_at:
            first_at.append(time.monotonic() - began)
        sent.append(message)

    await app(request_scope(), receive, send)
    return sent, first_at[0] if first_at else float("inf")


def test_a_silent_database_is_answered_503_before_the_handler_has_cleaned_up() -> None:
    cleaned_up_at: list[float] = []

    async def handler(scope: Scope, receive: Receive, send: Send) -> None:
        await receive()
        try:
            await asyncio.Event().wait()  # a query the frozen server never answers
        finally:
            await asyncio.sleep(1.0)  # cancelling it waits on that server too
            cleaned_up_at.append(time.monotonic())

    async def scenario() -> tuple[list[Message], float, float]:
        with silent_database() as url:
            watch = DatabaseWatch(url, PROBE_S)
            began = time.monotonic()
            sent, answered_after = await call(RequestDeadline(handler, DEADLINE_S, watch))
            await watch.close()
            return sent, answered_after, cleaned_up_at[0] - began

    sent, answered_after, cleaned_after = asyncio.run(scenario())
    assert sent[0]["status"] == 503
    assert dict(sent[0]["headers"])[b"retry-after"]
    assert len(sent) == 2
    assert not sent[1].get("more_body", False)
    # deadline + probe + one sweep interval, with room for a busy machine; the cleanup's 1 s
    # is not waited for
    assert answered_after < DEADLINE_S + PROBE_S + DEADLINE_S / 8 + 0.5
    assert answered_after < cleaned_after


def test_a_slow_request_on_a_database_that_answers_is_answered_by_its_handler(
    database_url: str,
) -> None:
    async def handler(scope: Scope, receive: Receive, send: Send) -> None:
        await receive()
        await asyncio.sleep(3 * DEADLINE_S)  # slow, but the database answers meanwhile
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"done"})

    async def scenario() -> list[Message]:
        watch = DatabaseWatch(database_url, 5.0)
        sent, _ = await call(RequestDeadline(handler, DEADLINE_S, watch))
        await watch.close()
        return sent

    sent = asyncio.run(scenario())
    assert [message.get("status") for message in sent] == [200, None]
    assert sent[1]["body"] == b"done"


def test_the_handlers_own_error_propagates() -> None:
    async def handler(scope: Scope, receive: Receive, send: Send) -> None:
        raise LookupError("the handler's own")

    async def scenario() -> None:
        with silent_database() as url:
            watch = DatabaseWatch(url, PROBE_S)
            try:
                await call(RequestDeadline(handler, DEADLINE_S, watch))
            finally:
                await watch.close()

    with pytest.raises(LookupError, match="the handler's own"):
        asyncio.run(scenario())
