"""Database plumbing: URL forms, the one engine per process, a session per job or command.

The server is asynchronous (SQLAlchemy AsyncEngine on psycopg 3) so that many vehicles' pings can
share one database round trip; command-line tools and migrations use a synchronous engine. The
request's session, a FastAPI dependency, is in `app.core.sessions`: this module does not import
the web framework, which was a quarter of every command's start-up.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import psycopg
from sqlalchemy import Engine, create_engine
from sqlalchemy.engine import make_url
from sqlalchemy.ext.asyncio import (
    AsyncEngine,
    create_async_engine,
)
from sqlalchemy.orm import Session, sessionmaker


class DatabaseUnavailable(Exception):
    """The database cannot be reached or started; the message says why in one line."""


def sqlalchemy_url(url: str) -> str:
    """The URL with the psycopg 3 driver named, as SQLAlchemy wants it."""
    for prefix in ("postgresql+psycopg://", "postgresql://", "postgres://"):
        if url.startswith(prefix):
            return "postgresql+psycopg://" + url[len(prefix) :]
    raise DatabaseUnavailable(f"SMOOTHFLEET_DATABASE_URL: not a PostgreSQL URL: {redact(url)}")


def libpq_url(url: str) -> str:
    """The URL as libpq (psycopg, psql) wants it."""
    return "postgresql://" + sqlalchemy_url(url)[len("postgresql+psycopg://") :]


def redact(url: str) -> str:
    """The URL with any password hidden, for messages and logs."""
    try:
        return make_url(url).render_as_string(hide_password=True)
    except Exception:  # noqa: BLE001 - an unparsable URL is shown as a placeholder
        return "<unparsable URL>"


def describe_target(url: str) -> str:
    """Host and database of a URL, for error messages."""
    parsed = make_url(sqlalchemy_url(url))
    host = parsed.host or parsed.query.get("host") or "localhost"
    port = f":{parsed.port}" if parsed.port else ""
    return f"{host}{port}/{parsed.database}"


def check_reachable(url: str, timeout_s: float = 5.0) -> None:
    """Connect once, raising DatabaseUnavailable with a one-line reason on failure."""
    try:
        with psycopg.connect(libpq_url(url), connect_timeout=max(1, int(timeout_s))):
            pass
    except psycopg.Error as error:
        reason = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise DatabaseUnavailable(
            f"cannot reach the database at {describe_target(url)}: {reason}"
        ) from None


def _connect_args(connect_timeout_s: float, statement_timeout_s: float) -> dict[str, Any]:
    return {
        "connect_timeout": max(1, int(connect_timeout_s)),
        "options": f"-c statement_timeout={int(statement_timeout_s * 1000)} -c timezone=UTC",
    }


def make_sync_engine(
    url: str, *, connect_timeout_s: float = 5.0, statement_timeout_s: float = 300.0
) -> Engine:
    """A synchronous engine for command-line tools, jobs and tests."""
    return create_engine(
        sqlalchemy_url(url),
        pool_pre_ping=True,
        connect_args=_connect_args(connect_timeout_s, statement_timeout_s),
    )


def make_async_engine(
    url: str,
    *,
    pool_size: int = 10,
    connect_timeout_s: float = 5.0,
    statement_timeout_s: float = 30.0,
) -> AsyncEngine:
    """The server's one engine."""
    return create_async_engine(
        sqlalchemy_url(url),
        pool_size=pool_size,
        max_overflow=pool_size,
        pool_timeout=connect_timeout_s,
        pool_pre_ping=True,
        connect_args=_connect_args(connect_timeout_s, statement_timeout_s),
    )


@contextmanager
def session_scope(engine: Engine) -> Iterator[Session]:
    """A session for a job or a command: commit on success, roll back on error."""
    factory = sessionmaker(engine, expire_on_commit=False)
    with factory() as session, session.begin():
        yield session
