"""A throwaway warehouse for a benchmark: an embedded PostgreSQL in a temporary folder,
migrated and seeded (the I-24 corridor and the 100-car roster), gone when the bench ends."""

from __future__ import annotations

import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy import Engine

from app.core.db import make_sync_engine, session_scope
from app.core.embedded import database_url, embedded_server, ensure_database
from app.migrate import upgrade
from app.seed import seed


@dataclass(frozen=True)
class BenchWarehouse:
    """The seeded database's URL, an engine on it, and a scratch folder beside it."""

    url: str
    engine: Engine
    scratch: Path


@contextmanager
def seeded_warehouse(prefix: str) -> Iterator[BenchWarehouse]:
    """A migrated and seeded database for one bench run; the engine is disposed after."""
    with (
        tempfile.TemporaryDirectory(prefix=prefix) as scratch,
        embedded_server(Path(scratch) / "pgdata", delete_on_exit=True) as server,
    ):
        ensure_database(server, "bench")
        url = database_url(server, "bench")
        engine = make_sync_engine(url)
        try:
            upgrade(engine)
            with session_scope(engine) as session:
                seed(session)
            yield BenchWarehouse(url, engine, Path(scratch))
        finally:
            engine.dispose()
