"""The request deadline's database probe owns every connection it opens, late ones included."""

from __future__ import annotations

import asyncio
import time

import psycopg

from app.core.db import libpq_url
from app.core.deadline import DatabaseWatch


def probe_connections(url: str) -> int:
    """Connections to this test's database other than the one counting them."""
    with psycopg.connect(libpq_url(url)) as connection:
        row = connection.execute(
            "SELECT count(*) FROM pg_stat_activity"
            " WHERE datname = current_database() AND pid <> pg_backend_pid()"
        ).fetchone()
    assert row is not None
    return int(row[0])


def probe_connections_once_settled(url: str) -> int:
    """The count once closed connections' server processes have gone (they exit just after
    their client closes); stops at 0 or after 5 s."""
    deadline = time.monotonic() + 5.0
    while (count := probe_connections(url)) and time.monotonic() < deadline:
        time.sleep(0.05)
    return count


def test_a_probe_that_answers_keeps_one_connection_and_closes_it(database_url: str) -> None:
    async def scenario() -> tuple[bool, bool, int]:
        watch = DatabaseWatch(database_url, probe_timeout_s=5.0)
        first = await watch.answers()
        second = await watch.answers()  # the same connection, not a second one
        open_while_running = await asyncio.to_thread(probe_connections, database_url)
        await watch.close()
        return first, second, open_while_running

    assert asyncio.run(scenario()) == (True, True, 1)
    assert probe_connections_once_settled(database_url) == 0


def test_an_attempt_abandoned_by_its_timeout_closes_the_connection_it_opens_late(
    database_url: str,
) -> None:
    async def scenario() -> tuple[bool, int]:
        # no database answers within a microsecond: the attempt is given up on, and the server
        # shuts the probe down while the attempt is still connecting
        watch = DatabaseWatch(database_url, probe_timeout_s=1e-6)
        answered = await watch.answers()
        await watch.close()
        await asyncio.sleep(0.5)  # the late connection arrives; the probe closes it itself
        left_open = await asyncio.to_thread(probe_connections_once_settled, database_url)
        return answered, left_open

    assert asyncio.run(scenario()) == (False, 0)
