"""`smoothfleet db` (migrations, URL, psql, backups, housekeeping) and `smoothfleet seed`."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import click
from sqlalchemy import text
from sqlalchemy.engine import URL, make_url

from app.core.db import libpq_url, make_sync_engine, redact, session_scope, sqlalchemy_url
from smoothfleet.cli.common import (
    CliError,
    console,
    database,
    output_file,
    replaced_on_success,
    settings,
)


@click.group()
def db() -> None:
    """The warehouse database: migrations, URL, psql, housekeeping."""


@db.command("upgrade")
@click.argument("revision", default="head")
def db_upgrade(revision: str) -> None:
    """Migrate the schema up to REVISION (default: head)."""
    from app.migrate import UnknownRevision, check_revision, upgrade

    try:
        check_revision(revision)
    except UnknownRevision as error:
        raise click.BadParameter(str(error), param_hint="REVISION") from None
    with database(settings()) as url:
        upgrade(make_sync_engine(url), revision)
    console.print(f"database at {revision}")


# "-1" (one revision down) is a revision, not an option: it was refused as "No such option".
@db.command("downgrade", context_settings={"ignore_unknown_options": True})
@click.argument("revision")
@click.option(
    "--yes",
    is_flag=True,
    help="Do not ask first (scripts): what the undone migrations created goes, with its data.",
)
def db_downgrade(revision: str, yes: bool) -> None:
    """Migrate the schema down to REVISION ("base" removes every table, "-1" one step).

    Says which migrations it undoes and asks first: undoing one drops what it created, the
    assignment history or the change log with their rows, and "base" every table (before
    2026-12-05 it asked nothing). Without a terminal to ask on, only --yes goes ahead."""
    from app.migrate import (
        UnknownRevision,
        check_revision,
        current_revision,
        downgrade,
        plan_downgrade,
    )

    try:
        check_revision(revision)
    except UnknownRevision as error:
        raise click.BadParameter(str(error), param_hint="REVISION") from None
    with database(settings()) as url:
        engine = make_sync_engine(url)
        with engine.connect() as connection:
            try:
                plan = plan_downgrade(connection, revision)
            except UnknownRevision as error:
                raise click.BadParameter(str(error), param_hint="REVISION") from None
        if plan.undone and not yes:
            _confirm_downgrade(revision, plan.undone)
        # to the target the listing was made for, not `revision` read again by Alembic
        downgrade(engine, plan.target)
        with engine.connect() as connection:
            reached = current_revision(connection)
    # the revision reached, not the one asked for: "-1" says nothing of where it went
    console.print(f"database at {reached or 'base (no table)'}")


def _confirm_downgrade(revision: str, undone: list[tuple[str, str]]) -> None:
    """Say what a downgrade undoes and ask; CliError when there is no terminal to ask on."""
    listing = "\n".join(f"  {name}  {what}" for name, what in undone)
    warning = (
        f"db downgrade {revision} undoes {len(undone)} migration(s); what they created goes, "
        f"with the data in it (back up first: smoothfleet db dump FILE):\n{listing}"
    )
    if not sys.stdin.isatty():
        raise CliError(f"{warning}\nnothing was changed: pass --yes to go on (no terminal to ask)")
    click.echo(warning, err=True)
    click.confirm("Downgrade?", abort=True, err=True)


@db.command("url")
def db_url() -> None:
    """Print the database URL (password hidden) the other commands use."""
    with database(settings()) as url:
        click.echo(redact(url))


def _for_child(url: str) -> tuple[str, dict[str, str]]:
    """The libpq URL without its password, and an environment for a child process (psql,
    pg_dump) that gives the password (PGPASSWORD) and opens the session in UTC (PGTZ), as the
    service's own sessions are: a command line is shown to every user of the host (`ps`), an
    environment only to its owner; and the warehouse's days and hours are UTC's, which a bound
    written without a zone is read in only when the session is (docs/analytics.md)."""
    parsed = make_url(sqlalchemy_url(url))
    environment = dict(os.environ, PGTZ="UTC")
    if parsed.password is not None:
        environment["PGPASSWORD"] = str(parsed.password)
        parsed = URL.create(
            parsed.drivername,
            parsed.username,
            None,
            parsed.host,
            parsed.port,
            parsed.database,
            parsed.query,
        )
    return libpq_url(parsed.render_as_string(hide_password=False)), environment


@db.command("psql", context_settings={"ignore_unknown_options": True})
@click.argument("psql_args", nargs=-1, type=click.UNPROCESSED)
def db_psql(psql_args: tuple[str, ...]) -> None:
    """Open psql on the database (the embedded server's own psql if none is installed)."""
    from app.core.embedded import bin_dir

    executable = shutil.which("psql") or str(bin_dir() / "psql")
    with database(settings()) as url:
        child_url, environment = _for_child(url)
        code = subprocess.call([executable, child_url, *psql_args], env=environment)
    if code:
        raise SystemExit(code)


@db.command("dump")
@click.argument("dump_file", metavar="FILE", type=click.Path(path_type=Path))
def db_dump(dump_file: Path) -> None:
    """Back up the database to FILE (pg_dump's custom format, for pg_restore).

    The embedded server stops when the last command using it exits, so the URL `db url` prints
    is dead by the time a pg_dump started after it connects: this runs pg_dump while the
    server is held. FILE is replaced only by a whole dump, written to disk before it is: the
    temporary file beside it is this process's own, so two dumps to one FILE never write into
    one file (before 2026-12-05 they shared `FILE.partial`, and the first renamed a file the
    second had truncated and half rewritten)."""
    output_file(dump_file, "FILE")
    current = settings()
    executable = _newest_client("pg_dump")
    with database(current) as url, replaced_on_success(dump_file) as partial:
        child_url, environment = _for_child(url)
        code = subprocess.call(
            [executable, "--format=custom", f"--file={partial}", child_url], env=environment
        )
        if code:
            raise CliError(f"pg_dump exited {code}: {dump_file} was left as it was")
        with partial.open("rb") as written:
            os.fsync(written.fileno())
    console.print(
        f"{dump_file}: {dump_file.stat().st_size:,} bytes; restore it into an empty database "
        f"with smoothfleet db restore {dump_file}"
    )


# Tables and views in any schema but PostgreSQL's own: a restore adds the dump's, and the
# analytics schema's views count as much as the public tables.
RELATIONS_HELD = text(
    "SELECT n.nspname || '.' || c.relname FROM pg_class c"
    " JOIN pg_namespace n ON n.oid = c.relnamespace"
    " WHERE c.relkind IN ('r', 'p', 'v', 'm')"
    " AND n.nspname NOT IN ('pg_catalog', 'information_schema')"
    " AND n.nspname NOT LIKE 'pg_toast%' ORDER BY 1"
)


@db.command("restore")
@click.argument(
    "dump_file", metavar="FILE", type=click.Path(exists=True, dir_okay=False, path_type=Path)
)
def db_restore(dump_file: Path) -> None:
    """Restore a `db dump` FILE into the database the commands use, which must be empty (a new
    SMOOTHFLEET_DATA_DIR, or a new database in SMOOTHFLEET_DATABASE_URL).

    All or nothing (one transaction). It runs the newest pg_restore at hand, as `db dump`
    runs the newest pg_dump: a dump of the embedded server's pg_dump is a format the system's
    older pg_restore refuses ("unsupported version (1.16) in file header" from Debian 12's),
    and the embedded server, which stops when the last command using it exits, is held while
    pg_restore runs. Objects are restored owned by the restoring role (`--no-owner`): a dump
    of compose's `smoothfleet` role restores into the embedded server's, and back."""
    from app.migrate import current_revision

    current = settings()
    executable = _newest_client("pg_restore")
    with database(current) as url:
        engine = make_sync_engine(url)
        with engine.connect() as connection:
            held = connection.execute(RELATIONS_HELD).scalars().all()
        if held:
            hint = (
                " (`db downgrade base` leaves alembic_version: drop it with smoothfleet db psql "
                "-c 'DROP TABLE alembic_version')"
                if held == ["public.alembic_version"]
                else ""
            )
            raise CliError(
                f"the database holds {len(held)} table(s) or view(s), {', '.join(held[:3])}"
                f"{' ...' if len(held) > 3 else ''}: restore into an empty one (a new "
                "SMOOTHFLEET_DATA_DIR, or createdb NEW and SMOOTHFLEET_DATABASE_URL)"
                f"{hint}; nothing was changed"
            )
        child_url, environment = _for_child(url)
        code = subprocess.call(
            [executable, "--single-transaction", "--no-owner", f"--dbname={child_url}", dump_file],
            env=environment,
        )
        if code:
            raise CliError(f"pg_restore exited {code}: nothing of {dump_file} was restored")
        with engine.connect() as connection:
            revision = current_revision(connection)
        engine.dispose()
    console.print(
        f"restored {dump_file}: database at {revision or 'base (no table)'}; "
        "`smoothfleet db upgrade` brings an older backup to head"
    )


def _newest_client(name: str) -> str:
    """The newest of PostgreSQL's client `name` at hand, the embedded server's or the
    system's: pg_dump refuses a server newer than itself (Debian 12's 15 against the embedded
    17), and pg_restore a dump format newer than its own, never an older one."""
    from app.core.embedded import bin_dir

    candidates = [str(bin_dir() / name), *filter(None, [shutil.which(name)])]

    def major(executable: str) -> int:
        try:
            answer = subprocess.run(
                [executable, "--version"], capture_output=True, text=True, check=True, timeout=10
            ).stdout
        except (OSError, subprocess.SubprocessError):
            return -1
        version = answer.rsplit(")", 1)[-1].split()
        return int(version[0].split(".")[0]) if version and version[0][:1].isdigit() else -1

    return max(candidates, key=major)


@db.command("maintain")
def db_maintain() -> None:
    """Create the coming days' ping partitions and drop those past retention."""
    from app.maintenance import maintain

    current = settings()
    with database(current) as url, make_sync_engine(url).begin() as connection:
        result = maintain(
            connection,
            ahead_days=current.ping_partitions_ahead_days,
            retention_days=current.ping_retention_days,
        )
    console.print(
        f"ping partitions: {result.partitions_created} created, "
        f"{result.partitions_dropped} dropped (retention {current.ping_retention_days} days), "
        f"{result.default_rows_deleted} older pings deleted from the default partition, "
        f"{result.status_reports_deleted} status reports past retention deleted, "
        f"{result.login_failures_deleted} failed logins a day old forgotten"
    )


@click.command("seed")
def seed_command() -> None:
    """Load the I-24-WB corridor, its segments and the 100-car roster (idempotent)."""
    from app.seed import seed

    with database(settings()) as url, session_scope(make_sync_engine(url)) as session:
        counts = seed(session)
    console.print(
        f"seeded: {counts.corridors} corridor(s), {counts.inrix_segments} INRIX segments, "
        f"{counts.i24_segments} sub-segments, {counts.vehicles} vehicles"
    )
    for controller, sha256 in counts.policies.items():
        console.print(f"{controller}: policy {sha256[:12]} held for the roster's cars that run it")
