"""`smoothfleet`: the server-side command line (see docs/interfaces.md, "Command line").

Every command that needs the database gets it from `database()`: the server named by
SMOOTHFLEET_DATABASE_URL, or else the embedded PostgreSQL under SMOOTHFLEET_DATA_DIR, started
for the command and stopped when the last process using it exits. Expected failures (a bad
setting, an unreachable server, a bad CSV row, a taken port) end with one line on stderr and a
non-zero exit code, never a traceback.
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
from datetime import UTC, datetime
from pathlib import Path
from types import FrameType
from typing import NoReturn

import click
from psycopg.errors import UndefinedTable
from pydantic import ValidationError
from rich.table import Table
from sqlalchemy.exc import IntegrityError, ProgrammingError

from app.core.config import Settings, SettingsError, get_settings
from app.core.db import (
    DatabaseUnavailable,
    libpq_url,
    make_sync_engine,
    redact,
    session_scope,
)
from app.core.metrics import MULTIPROCESS_DIR_ENV
from app.core.security import TOKEN_ROLES, issue_token
from app.users.service import (
    OPS_ROLES,
    UserError,
    check_new_user,
    list_users,
    new_password,
    save_user,
)
from app.vehicles.schemas import RosterRow
from app.vehicles.service import (
    RosterError,
    first_error,
    list_vehicles,
    parse_roster_csv,
    upsert_vehicles,
)
from smoothfleet.cli.common import (
    CliError,
    CommandGroup,
    console,
    database,
    fleet_options,
    output_file,
    settings,
    write_output_with,
)

# Command groups imported only when named (their imports are most of the start-up time).
LAZY_GROUPS = {
    name: f"smoothfleet.cli.{name}:{name}"
    for name in ("inrix", "sim", "planner", "motion", "policy")
}


@click.group(
    cls=CommandGroup,
    lazy=LAZY_GROUPS,
    context_settings={"help_option_names": ["-h", "--help"]},
)
def cli() -> None:
    """smoothfleet: run a fleet of traffic-smoothing vehicles (server side)."""


# --- db ------------------------------------------------------------------------------------


@cli.group()
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
def db_downgrade(revision: str) -> None:
    """Migrate the schema down to REVISION ("base" removes every table, "-1" one step)."""
    from app.migrate import UnknownRevision, check_revision, current_revision, downgrade

    try:
        check_revision(revision)
    except UnknownRevision as error:
        raise click.BadParameter(str(error), param_hint="REVISION") from None
    with database(settings()) as url:
        engine = make_sync_engine(url)
        downgrade(engine, revision)
        with engine.connect() as connection:
            reached = current_revision(connection)
    # the revision reached, not the one asked for: "-1" says nothing of where it went
    console.print(f"database at {reached or 'base (no table)'}")


@db.command("url")
def db_url() -> None:
    """Print the database URL (password hidden) the other commands use."""
    with database(settings()) as url:
        click.echo(redact(url))


@db.command("psql", context_settings={"ignore_unknown_options": True})
@click.argument("psql_args", nargs=-1, type=click.UNPROCESSED)
def db_psql(psql_args: tuple[str, ...]) -> None:
    """Open psql on the database (the embedded server's own psql if none is installed)."""
    from app.core.embedded import bin_dir

    executable = shutil.which("psql") or str(bin_dir() / "psql")
    with database(settings()) as url:
        code = subprocess.call([executable, libpq_url(url), *psql_args])
    if code:
        raise SystemExit(code)


@db.command("dump")
@click.argument("dump_file", metavar="FILE", type=click.Path(path_type=Path))
def db_dump(dump_file: Path) -> None:
    """Back up the database to FILE (pg_dump's custom format, for pg_restore).

    The embedded server stops when the last command using it exits, so the URL `db url` prints
    is dead by the time a pg_dump started after it connects: this runs pg_dump while the
    server is held. FILE is replaced only by a whole dump."""
    output_file(dump_file, "FILE")
    current = settings()
    executable = _newest_pg_dump()
    partial = dump_file.with_name(f"{dump_file.name}.partial")
    with database(current) as url:
        code = subprocess.call([executable, "--format=custom", f"--file={partial}", libpq_url(url)])
    if code:
        partial.unlink(missing_ok=True)
        raise CliError(f"pg_dump exited {code}: {dump_file} was left as it was")
    partial.replace(dump_file)
    console.print(
        f"{dump_file}: {dump_file.stat().st_size:,} bytes; restore it into an empty database "
        f"with pg_restore --dbname=URL {dump_file}"
    )


def _newest_pg_dump() -> str:
    """The newest pg_dump at hand, the embedded server's or the system's: pg_dump refuses a
    server newer than itself (Debian 12's 15 against the embedded 17), never an older one."""
    from app.core.embedded import bin_dir

    candidates = [str(bin_dir() / "pg_dump"), *filter(None, [shutil.which("pg_dump")])]

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
        f"{result.status_reports_deleted} status reports past retention deleted"
    )


# --- seed, vehicles, tokens ---------------------------------------------------------------


@cli.command("seed")
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


@cli.group()
def vehicles() -> None:
    """The fleet roster."""


@vehicles.command("list")
def vehicles_list() -> None:
    """Show the roster."""
    with database(settings()) as url, session_scope(make_sync_engine(url)) as session:
        rows = list(list_vehicles(session))
        table = Table(
            "vehicle", "make", "model", "year", "actuation", "route", "lane", "controller", "active"
        )
        for vehicle in rows:
            table.add_row(
                vehicle.vehicle_id,
                vehicle.make,
                vehicle.model,
                str(vehicle.year),
                vehicle.actuation,
                vehicle.route,
                str(vehicle.assigned_lane),
                vehicle.controller_name,
                "maintenance" if vehicle.is_in_maintenance else str(vehicle.is_active).lower(),
            )
    console.print(table)
    console.print(f"{len(rows)} vehicle(s)")


@vehicles.command("add")
@click.option("--id", "vehicle_id", required=True, help="Roster id, e.g. SF-101.")
@click.option("--vin", required=True)
@click.option("--make", required=True)
@click.option("--model", required=True)
@click.option("--year", required=True, type=int)
@click.option("--actuation", required=True, type=click.Choice(["acc", "accel"]))
@click.option("--corridor", "corridor_id", default="I-24-WB", show_default=True)
@click.option("--route", required=True)
@click.option("--lane", "assigned_lane", required=True, type=int)
@click.option("--controller", "controller_name", required=True)
@click.option("--params", "controller_params", default="{}", help="Controller params as JSON.")
def vehicles_add(**fields: object) -> None:
    """Add one vehicle (or update it if the id exists)."""
    try:
        row = RosterRow.model_validate(fields)
    except ValidationError as error:
        raise CliError(f"vehicle: {first_error(error)}") from None
    with database(settings()) as url:
        _write_roster(url, [row], label=None)
    console.print(f"vehicle {row.vehicle_id} saved")


@vehicles.command("import")
@click.argument("csv_file", type=click.Path(path_type=Path))
def vehicles_import(csv_file: Path) -> None:
    """Import a roster CSV (columns as seed_data/roster.csv) in one transaction."""
    rows = parse_roster_csv(csv_file)
    with database(settings()) as url:
        written = _write_roster(url, rows, label=csv_file.name)
    console.print(f"imported {written} vehicle(s) from {csv_file}")


def _write_roster(url: str, rows: list[RosterRow], *, label: str | None) -> int:
    try:
        with session_scope(make_sync_engine(url)) as session:
            return upsert_vehicles(session, rows, update_existing=True, label=label)
    except IntegrityError as error:
        diag = getattr(error.orig, "diag", None)
        reason = (diag.message_detail or diag.message_primary) if diag else None
        source = label if label is not None else f"vehicle {rows[0].vehicle_id}"
        raise CliError(f"{source}: refused by the database: {reason or error.orig}") from None


@cli.group()
def tokens() -> None:
    """API bearer tokens."""


@tokens.command("create")
@click.option("--role", required=True, type=click.Choice(TOKEN_ROLES))
@click.option("--vehicle", "vehicle_id", help="The vehicle a vehicle token is bound to.")
@click.option("--name", default="", help="A note on who holds the token.")
def tokens_create(role: str, vehicle_id: str | None, name: str) -> None:
    """Issue a token and print it once (only its hash is stored)."""
    if (role == "vehicle") != (vehicle_id is not None):
        raise CliError("tokens create: --vehicle is required for --role vehicle, and only there")
    with database(settings()) as url:
        try:
            with session_scope(make_sync_engine(url)) as session:
                token = issue_token(session, role, vehicle_id=vehicle_id, name=name)  # type: ignore[arg-type]
        except IntegrityError:
            raise CliError(f"tokens create: unknown vehicle {vehicle_id}") from None
    click.echo(token)


@tokens.command("revoke")
@click.option("--id", "token_id", type=int, help="The token's id (see `tokens list`).")
@click.option("--vehicle", "vehicle_id", help="Revoke every live token of this vehicle.")
@click.option(
    "--token-stdin", is_flag=True, help="Read the token itself from standard input (one line)."
)
def tokens_revoke(token_id: int | None, vehicle_id: str | None, token_stdin: bool) -> None:
    """Revoke tokens; servers refuse them within SMOOTHFLEET_TOKEN_CACHE_TTL_S seconds."""
    from app.core.security import revoke_tokens

    token = sys.stdin.readline().strip() if token_stdin else None
    if sum(value is not None for value in (token_id, vehicle_id, token)) != 1:
        raise CliError("tokens revoke: give exactly one of --id, --vehicle, --token-stdin")
    with database(settings()) as url, session_scope(make_sync_engine(url)) as session:
        revoked = revoke_tokens(session, token_id=token_id, vehicle_id=vehicle_id, token=token)
    if not revoked:
        raise CliError("tokens revoke: no live token matches")
    console.print(f"revoked token(s) {', '.join(str(number) for number in revoked)}")


@tokens.command("list")
def tokens_list() -> None:
    """Show issued tokens (never the tokens themselves: only their hashes are stored)."""
    from app.core.security import list_tokens

    table = Table("id", "kind", "role", "vehicle", "name", "created", "last used", "revoked")
    with database(settings()) as url, session_scope(make_sync_engine(url)) as session:
        for row in list_tokens(session):
            table.add_row(
                str(row.token_id),
                row.kind,
                row.role or "",
                row.vehicle_id or "",
                row.name,
                f"{row.created_at:%Y-%m-%d %H:%M}",
                f"{row.last_used_at:%Y-%m-%d %H:%M}" if row.last_used_at else "",
                f"{row.revoked_at:%Y-%m-%d %H:%M}" if row.revoked_at else "",
            )
    console.print(table)


# --- users (dashboard logins) -------------------------------------------------------------


@cli.group()
def users() -> None:
    """Dashboard users (roles viewer, operator, admin)."""


@users.command("add")
@click.argument("username")
@click.option("--role", required=True, type=click.Choice(OPS_ROLES))
@click.option(
    "--password-stdin", is_flag=True, help="Read the password from standard input (one line)."
)
def users_add(username: str, role: str, password_stdin: bool) -> None:
    """Create a dashboard user, or reset an existing user's role and password."""
    if password_stdin:
        password = sys.stdin.readline().rstrip("\r\n")
    else:
        password = click.prompt("password", hide_input=True, confirmation_prompt=True)
    try:
        check_new_user(username, role, password)
    except UserError as error:
        raise CliError(f"users add: {error}") from None
    with database(settings()) as url, session_scope(make_sync_engine(url)) as session:
        created = save_user(session, username, role, password)
    console.print(f"user {username} {'created' if created else 'updated'} with role {role}")


@users.command("list")
def users_list() -> None:
    """Show the dashboard users."""
    with database(settings()) as url, session_scope(make_sync_engine(url)) as session:
        table = Table("user", "role", "last login", "failed logins")
        for user in list_users(session):
            last = user.last_login_at.isoformat(timespec="seconds") if user.last_login_at else ""
            table.add_row(user.username, user.role, last, str(user.failed_logins))
    console.print(table)


# --- analytics -----------------------------------------------------------------------------


def _moment(value: str | None, option: str) -> datetime | None:
    """An ISO 8601 date or time from an option (UTC when it names no zone)."""
    if value is None:
        return None
    try:
        moment = datetime.fromisoformat(value)
    except ValueError:
        raise CliError(f"{option}: not an ISO 8601 date or time: {value!r}") from None
    moment = moment if moment.tzinfo is not None else moment.replace(tzinfo=UTC)
    try:
        moment.astimezone(UTC)
    except OverflowError:
        raise CliError(f"{option}: {value!r} is out of range once read in UTC") from None
    return moment


@cli.group("analytics")
def analytics_group() -> None:
    """The analytics views (schema `analytics`, docs/analytics.md)."""


@analytics_group.command("list")
def analytics_list() -> None:
    """Name the views and what one row of each is."""
    from app.analytics import VIEWS

    table = Table("view", "one row per", "time column")
    for view in VIEWS.values():
        table.add_row(view.name, view.grain, view.time_column)
    console.print(table)


@analytics_group.command("export")
@click.argument("view_name")
@click.option("--since", help="From this ISO 8601 date or time (UTC unless a zone is given).")
@click.option("--until", help="Up to (not including) this date or time.")
@click.option("--vehicle", "vehicle_id", help="Only this vehicle (views with a vehicle_id).")
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, allow_dash=True),
    default="-",
    show_default=True,
    help="CSV file to write (- for standard output).",
)
def analytics_export(
    view_name: str, since: str | None, until: str | None, vehicle_id: str | None, output: str
) -> None:
    """Export one analytics view as CSV (header row, ISO 8601 times in UTC).

    The rows are read before the file is written, and the file is replaced only when it is
    whole: a refused request or a failed query leaves an earlier export as it was."""
    from app.analytics import ViewRequestError, export_csv, read_view, view_query

    window = {"since": _moment(since, "--since"), "until": _moment(until, "--until")}
    try:  # every mistake in the request named before the database starts
        view_query(view_name, vehicle_id=vehicle_id, **window)
    except ViewRequestError as error:
        raise CliError(f"analytics export: {error}") from None
    if output != "-":
        output_file(Path(output), "--output")
    with database(settings()) as url, make_sync_engine(url).connect() as connection:
        frame = read_view(connection, view_name, vehicle_id=vehicle_id, **window)
    if output == "-":
        rows = export_csv(frame, sys.stdout)
    else:

        def write(path: Path) -> None:
            with path.open("w", encoding="utf-8", newline="") as out:
                export_csv(frame, out)

        write_output_with(Path(output), write)
        rows = len(frame)
    click.echo(f"{rows} row(s) of analytics.{view_name}", err=True)


# --- serve, demo ---------------------------------------------------------------------------


def ensure_port_free(host: str, port: int) -> None:
    """Fail with one line if the port is taken, before any server starts."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError as error:
            if error.errno == errno.EADDRINUSE:
                raise CliError(
                    f"port {port} on {host} is already in use (choose another with --port "
                    "or SMOOTHFLEET_PORT)"
                ) from None
            raise CliError(f"cannot listen on {host}:{port}: {error.strerror}") from None


WORKER_STARTUP_TIMEOUT_S = 120


def run_server(url: str, current: Settings, *, migrate: bool) -> None:
    """Migrate (under a lock, so replicas do it once) and run uvicorn until stopped."""
    import uvicorn

    from app.migrate import upgrade

    if migrate:
        upgrade(make_sync_engine(url))
    # Workers are separate processes: they read the resolved URL from the environment.
    os.environ["SMOOTHFLEET_DATABASE_URL"] = url
    get_settings.cache_clear()
    metrics_dir = None
    if current.workers > 1 and not os.environ.get(MULTIPROCESS_DIR_ENV):
        # /metrics sums every worker's counters through this directory (app/core/metrics.py).
        metrics_dir = tempfile.mkdtemp(prefix="smoothfleet-metrics-")
        os.environ[MULTIPROCESS_DIR_ENV] = metrics_dir
    try:
        uvicorn.run(
            "smoothfleet.server:create_app",
            factory=True,
            host=current.host,
            port=current.port,
            workers=current.workers,
            log_level="info",
            access_log=False,
            # Forwarded-for headers are the app's to believe, from SMOOTHFLEET_TRUSTED_PROXIES
            # only (uvicorn's own default trusts any peer on 127.0.0.1).
            proxy_headers=False,
            # A worker imports the whole app (pandas, the dashboard) before it answers the
            # supervisor; uvicorn's 5 s default restarts it forever on a loaded small machine.
            timeout_worker_healthcheck=WORKER_STARTUP_TIMEOUT_S,
        )
    finally:
        if metrics_dir is not None:
            shutil.rmtree(metrics_dir, ignore_errors=True)


@cli.command("serve")
@click.option("--host", help="Listen address (SMOOTHFLEET_HOST).")
@click.option("--port", type=int, help="Listen port (SMOOTHFLEET_PORT).")
@click.option("--workers", type=int, help="uvicorn worker processes (SMOOTHFLEET_WORKERS).")
@click.option("--no-migrate", is_flag=True, help="Do not run migrations before serving.")
@click.option("--no-planner", is_flag=True, help="Do not run the planner schedule in this server.")
def serve(
    host: str | None, port: int | None, workers: int | None, no_migrate: bool, no_planner: bool
) -> None:
    """Run the API and dashboard (and the planner schedule unless --no-planner)."""
    if no_planner:
        # The workers read their settings from the environment.
        os.environ["SMOOTHFLEET_PLANNER_ENABLED"] = "false"
        get_settings.cache_clear()
    current = _with_overrides(host=host, port=port, workers=workers)
    ensure_port_free(current.host, current.port)
    with database(current) as url:
        run_server(url, current, migrate=not no_migrate)


DEMO_ADMIN = "admin"


DEMO_DATABASE = "smoothfleet_demo"


@cli.command("demo")
@click.option("--host", help="Listen address (SMOOTHFLEET_HOST).")
@click.option("--port", type=int, help="Listen port (SMOOTHFLEET_PORT).")
@click.option(
    "--keep",
    is_flag=True,
    help="Keep the previous run's demo database (maintenance flags, users, plans, pings).",
)
@click.option(
    "--rl",
    is_flag=True,
    help="Run the fleet on the committed RL policies: upload them and assign rl_acc / rl_accel "
    "by sha256 to every car (each car downloads its policy).",
)
@fleet_options
def demo(
    host: str | None,
    port: int | None,
    keep: bool,
    rl: bool,
    duration: float | None,
    vehicles: int,
) -> None:
    """Everything on one machine: embedded database, migrations, seed, API, dashboard, planner,
    a simulated INRIX feed and a simulated fleet whose cars run the real vehicle agent.

    The embedded server gets a database of the demo's own, made afresh each run unless --keep;
    with SMOOTHFLEET_DATABASE_URL set, the demo uses that database as it is."""
    current = _with_overrides(host=host, port=port)
    ensure_port_free(current.host, current.port)
    if current.database_url is not None:
        console.print("SMOOTHFLEET_DATABASE_URL is set: the demo uses that database as it is")
        with database(current) as url:
            _demo_on(url, current, duration, vehicles, rl=rl)
        return
    from app.core.embedded import (
        database_url,
        drop_database,
        embedded_server,
        ensure_database,
        pgdata_dir,
    )

    with embedded_server(pgdata_dir(current.data_dir)) as server_url:
        if not keep:
            drop_database(server_url, DEMO_DATABASE)
        ensure_database(server_url, DEMO_DATABASE)
        _demo_on(database_url(server_url, DEMO_DATABASE), current, duration, vehicles, rl=rl)


def _say_whole(line: str) -> None:
    """One line of the demo's output, never wrapped at the terminal's width (a status line is
    read, and grepped from a log, as one line)."""
    console.print(line, soft_wrap=True)


def _demo_on(
    url: str, current: Settings, duration: float | None, vehicles: int, *, rl: bool
) -> None:
    from app.migrate import upgrade
    from app.policies.service import ManifestConflict, assign_shipped_policies
    from app.seed import seed
    from smoothfleet.cli.demo import DemoError, run_demo

    engine = make_sync_engine(url)
    upgrade(engine)
    admin_password = new_password()
    try:
        with session_scope(engine) as session:
            counts = seed(session)
            save_user(session, DEMO_ADMIN, "admin", admin_password)
            policies = assign_shipped_policies(session) if rl else {}
    except ManifestConflict as error:
        raise CliError(
            f"demo --rl: {error}; the kept database holds it as an earlier run stored it, and a "
            "stored policy's manifest never changes: run the demo without --keep"
        ) from None
    finally:
        engine.dispose()
    public = (current.public_url or f"http://{current.host}:{current.port}").rstrip("/")
    console.print(f"[bold]smoothfleet demo[/bold]: database {redact(url)}")
    console.print(f"seeded {counts.vehicles} vehicles on {counts.i24_segments} sub-segments")
    for controller, sha256 in counts.policies.items():
        _say_whole(f"{controller}: policy {sha256[:12]} held for the seeded cars that run it")
    for controller, sha256 in policies.items():
        _say_whole(f"{controller}: policy {sha256[:12]} assigned to every car it can drive")
        if controller not in counts.policies:
            # The roster follows the simulator's verdict; --rl overrides it, and says so.
            _say_whole(
                f"{controller}: the seed roster does not run it (the simulator's verdict is not "
                "to assign it: docs/simulation.md); --rl runs it as the paper's fleet did"
            )
    console.print(f"dashboard: {public}/   login: {DEMO_ADMIN} / {admin_password} (new each run)")
    console.print(f"API docs: {public}/docs   health: {public}/readyz   (Ctrl-C stops)")
    try:
        summary = run_demo(url, current, duration_s=duration, vehicles=vehicles, say=_say_whole)
    except DemoError as error:
        raise CliError(f"demo: {error}") from None
    for line in summary.lines():
        console.print(line)


def _with_overrides(**overrides: object) -> Settings:
    from app.core.config import load_settings

    given = {name: value for name, value in overrides.items() if value is not None}
    if not given:
        return settings()
    return load_settings(**given)


# --- entry point ---------------------------------------------------------------------------


def _exit_on_sigterm(signum: int, frame: FrameType | None) -> NoReturn:
    """SIGTERM unwinds like Ctrl-C, so the embedded database is stopped on the way out.

    Further SIGTERMs and Ctrl-Cs are ignored from here on: the clean-up must not be cut short.
    """
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    raise SystemExit(128 + signum)


def fail(message: str) -> NoReturn:
    """Print one line and exit non-zero."""
    click.echo(f"smoothfleet: error: {message}", err=True)
    raise SystemExit(1)


def main() -> None:
    """Console-script entry point."""
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    try:
        cli(standalone_mode=False)
    except click.exceptions.Abort:
        raise SystemExit(130) from None
    except click.ClickException as error:
        error.show()
        raise SystemExit(error.exit_code) from None
    except (SettingsError, DatabaseUnavailable, RosterError, CliError) as error:
        fail(str(error))
    except ProgrammingError as error:
        if isinstance(error.orig, UndefinedTable):
            fail("the database has no smoothfleet schema yet: run `smoothfleet db upgrade`")
        raise
    except KeyboardInterrupt:
        raise SystemExit(130) from None
    except SystemExit:
        raise
    except Exception as error:  # a bug: still one line for the user, details in the log
        if os.environ.get("SMOOTHFLEET_DEBUG"):
            raise
        fail(f"unexpected {type(error).__name__}: {error} (set SMOOTHFLEET_DEBUG=1 for details)")
