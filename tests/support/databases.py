"""Databases for tests: one embedded server per session, a fresh database per test.

Migrations run once into a template database; each test gets `CREATE DATABASE ... TEMPLATE`,
which copies the migrated (and optionally seeded) schema in a few tens of milliseconds, so code
under test can commit freely and tests never see each other's rows.
"""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager

import psycopg
from psycopg import sql
from sqlalchemy import Engine, text

from app.core.db import libpq_url, make_sync_engine, session_scope
from app.core.embedded import database_url
from app.migrate import upgrade

_counter = itertools.count(1)


def admin_execute(server_url: str, statement: sql.Composable) -> None:
    """Run one statement on the server's maintenance database, outside a transaction."""
    with psycopg.connect(libpq_url(server_url), autocommit=True) as conn:
        conn.execute(statement)


def create_template(server_url: str, name: str, *, seeded: bool) -> str:
    """A migrated (and optionally seeded) database to copy tests' databases from."""
    admin_execute(
        server_url, sql.SQL("DROP DATABASE IF EXISTS {} WITH (FORCE)").format(sql.Identifier(name))
    )
    admin_execute(server_url, sql.SQL("CREATE DATABASE {}").format(sql.Identifier(name)))
    url = database_url(server_url, name)
    engine = make_sync_engine(url)
    try:
        upgrade(engine)
        if seeded:
            from app.seed import seed

            with session_scope(engine) as session:
                seed(session)
    finally:
        engine.dispose()
    return url


@contextmanager
def database_from_template(server_url: str, template: str) -> Iterator[str]:
    """A fresh copy of `template`, dropped afterwards."""
    name = f"t{os.getpid()}_{next(_counter)}"
    admin_execute(
        server_url,
        sql.SQL("CREATE DATABASE {} TEMPLATE {}").format(
            sql.Identifier(name), sql.Identifier(template)
        ),
    )
    try:
        yield database_url(server_url, name)
    finally:
        admin_execute(
            server_url,
            sql.SQL("DROP DATABASE IF EXISTS {} WITH (FORCE)").format(sql.Identifier(name)),
        )


def sessions_waiting_on_a_lock(engine: Engine, within_s: float = 10.0) -> int:
    """How many sessions wait on a lock, as soon as any does (0 if none within `within_s`):
    a test holding a transaction open lets the code under test meet it first."""
    deadline = time.monotonic() + within_s
    with engine.connect() as watcher:
        while True:
            waiting = int(
                watcher.execute(
                    text(
                        "SELECT count(*) FROM pg_stat_activity "
                        "WHERE wait_event_type = 'Lock' AND datname = current_database()"
                    )
                ).scalar_one()
            )
            # pg_stat_activity is read once a transaction: a new one sees the sessions as now
            watcher.rollback()
            if waiting or time.monotonic() > deadline:
                return waiting
            time.sleep(0.05)
