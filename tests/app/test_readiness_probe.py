"""`/readyz` answers anyone: what it says of an unreachable database."""

from __future__ import annotations

import asyncio
import logging

import httpx
import pytest

from app.core.config import Settings
from app.main import create_api


def test_an_unreachable_database_is_named_as_such_and_its_address_only_logged(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The answer carried the driver's first line: the host, port, database and user (or the
    socket's path) to any unauthenticated caller; it goes to the log instead."""
    app = create_api(
        Settings(
            database_url="postgresql://fleetdb_user:secret@127.0.0.1:9/fleet_db",
            db_connect_timeout_s=1,
        )
    )

    async def ask() -> httpx.Response:
        async with (
            app.router.lifespan_context(app),
            httpx.AsyncClient(transport=httpx.ASGITransport(app), base_url="http://api") as client,
        ):
            return await client.get("/readyz")

    with caplog.at_level(logging.WARNING):
        answer = asyncio.run(ask())
    assert answer.status_code == 503
    assert answer.json() == {"status": "unavailable", "reason": "database unreachable"}
    assert "127.0.0.1" in caplog.text
