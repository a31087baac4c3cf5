"""Programmatic Alembic: `smoothfleet db upgrade|downgrade`, `/readyz` and the tests use it."""

from __future__ import annotations

import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from alembic.script.revision import ResolutionError, RevisionError
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


# A downgrade's relative target: N steps below the database's revision ("-1") or below a named
# one ("0012-2").
STEPS_DOWN = re.compile(r"(?P<start>[^+-]*)-(?P<steps>\d+)")


@dataclass(frozen=True)
class DowngradePlan:
    """Where a downgrade goes (a revision id, or "base") and (revision, what it did) of each
    migration it undoes, newest first."""

    target: str
    undone: list[tuple[str, str]]


def plan_downgrade(connection: Connection, revision: str) -> DowngradePlan:
    """What a downgrade to `revision` does from the database's revision. A relative target is
    counted down from the database's revision (or the one it names), as Alembic's downgrade
    counts it: listing it with Alembic's `iterate_revisions` counted from the newest migration
    instead, so "-1" one step below head listed nothing, asked nothing, and dropped a column.
    UnknownRevision for a target that is not at or below the database's revision."""
    current = current_revision(connection)
    if current is None:
        return DowngradePlan("base", [])
    script = ScriptDirectory.from_config(alembic_config())
    target = revision
    relative = STEPS_DOWN.fullmatch(revision)
    if relative is not None:
        target = _steps_below(script, relative["start"] or current, int(relative["steps"]))
    elif RELATIVE_REVISION.fullmatch(revision):
        raise UnknownRevision(f"a downgrade goes down: {revision!r} counts up")
    try:
        undone = list(script.iterate_revisions(current, target))
    except (RevisionError, CommandError) as error:
        raise UnknownRevision(f"cannot downgrade from {current} to {revision!r}: {error}") from None
    return DowngradePlan(
        target, [(one.revision, (one.doc or "").splitlines()[0]) for one in undone]
    )


def _steps_below(script: ScriptDirectory, start: str, steps: int) -> str:
    """The revision `steps` migrations below `start` ("base" below the first)."""
    try:
        found = script.get_revision(start)
    except (RevisionError, CommandError) as error:
        raise UnknownRevision(f"no migration revision {start!r} ({error})") from None
    if found is None:  # "base": nothing is below it
        raise UnknownRevision(f"no migration is below {start!r}")
    below: str | None = found.revision
    for taken in range(steps):
        if below is None:
            raise UnknownRevision(f"{start} is only {taken} step(s) above base, not {steps}")
        down = script.get_revision(below).down_revision
        if isinstance(down, tuple | list):
            raise UnknownRevision(f"{below} merges {len(down)} branches: name the target")
        below = down
    return below or "base"


def downgrade(engine: Engine, revision: str) -> None:
    """Migrate the database down to `revision` ("base" empties it), in one transaction."""
    check_revision(revision)
    with engine.begin() as connection:
        connection.execute(MIGRATION_LOCK_SQL)
        config = alembic_config()
        config.attributes["connection"] = connection
        command.downgrade(config, revision)
