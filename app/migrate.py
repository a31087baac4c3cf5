"""Programmatic Alembic: `smoothfleet db upgrade|downgrade`, `/readyz` and the tests use it."""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from alembic.script.revision import ResolutionError
from alembic.util import CommandError
from sqlalchemy import Connection, Engine, text

# The migration scripts are this package's data: Alembic runs them (their env.py imports
# app.models), so they are located as files, never imported from here.
MIGRATIONS_DIR = Path(str(resources.files("migrations")))


def alembic_config(url: str | None = None) -> Config:
    """An Alembic config pointing at the packaged migrations."""
    config = Config(str(MIGRATIONS_DIR / "alembic.ini"))
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    if url is not None:
        config.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return config


def head_revision() -> str:
    """The single head of the migration history."""
    heads = ScriptDirectory.from_config(alembic_config()).get_heads()
    if len(heads) != 1:
        raise RuntimeError(f"migrations have {len(heads)} heads: {', '.join(heads)}")
    return heads[0]


class UnknownRevision(ValueError):
    """A migration target that names no revision of the packaged migrations."""


# A relative target ("-1", "+2", "0003+1"): Alembic resolves it against the database's state.
RELATIVE_REVISION = re.compile(r".*[+-]\d+")


def check_revision(revision: str) -> None:
    """Refuse, before any database is touched, a target that names no revision (`head`, `base`,
    an id or its unique prefix; relative targets are left to Alembic)."""
    if RELATIVE_REVISION.fullmatch(revision):
        return
    script = ScriptDirectory.from_config(alembic_config())
    try:
        script.revision_map.get_revisions(revision)
    except ResolutionError as error:
        known = ", ".join(reversed([one.revision for one in script.walk_revisions()]))
        raise UnknownRevision(
            f"no migration revision {revision!r} ({error}); the revisions: base, {known}, head"
        ) from None


def current_revision(connection: Connection) -> str | None:
    """The revision the database is at (None for an empty database)."""
    return MigrationContext.configure(connection).get_current_revision()


# Replicas starting together migrate once: the others wait on this lock, then find nothing to do.
MIGRATION_LOCK_SQL = text("SELECT pg_advisory_xact_lock(hashtext('smoothfleet-migrations'))")


def upgrade(engine: Engine, revision: str = "head") -> None:
    """Migrate the database up to `revision`, all steps in one transaction."""
    check_revision(revision)
    with engine.begin() as connection:
        connection.execute(MIGRATION_LOCK_SQL)
        config = alembic_config()
        config.attributes["connection"] = connection
        command.upgrade(config, revision)


def revisions_undone(connection: Connection, revision: str) -> list[tuple[str, str]]:
    """(revision, what it did) of each migration a downgrade to `revision` undoes, newest
    first; UnknownRevision for a target that is not below the database's revision."""
    current = current_revision(connection)
    if current is None:
        return []
    script = ScriptDirectory.from_config(alembic_config())
    try:
        undone = list(script.iterate_revisions(current, revision))
    except (ResolutionError, CommandError) as error:
        raise UnknownRevision(f"cannot downgrade from {current} to {revision!r}: {error}") from None
    return [(one.revision, (one.doc or "").splitlines()[0]) for one in undone]


def downgrade(engine: Engine, revision: str) -> None:
    """Migrate the database down to `revision` ("base" empties it), in one transaction."""
    check_revision(revision)
    with engine.begin() as connection:
        connection.execute(MIGRATION_LOCK_SQL)
        config = alembic_config()
        config.attributes["connection"] = connection
        command.downgrade(config, revision)
