"""The command line: one clear line for every expected failure, nothing half-written."""

from __future__ import annotations

import hashlib
import signal
import socket
import subprocess
import time
from pathlib import Path

import httpx
import psutil
import pytest
from psycopg import sql
from sqlalchemy import Engine, text

from app.core.db import make_sync_engine
from app.core.embedded import database_url as embedded_url
from app.migrate import current_revision, head_revision
from app.vehicles.service import RosterError, parse_roster_csv
from tests.support.databases import admin_execute, database_from_template
from tests.support.servers import cli_env, free_port, run_cli, smoothfleet_command, wait_until_ready
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES

ROSTER_HEADER = (
    "vehicle_id,vin,make,model,year,actuation,corridor_id,route,assigned_lane,"
    "controller_name,controller_params\n"
)


def write_roster(path: Path, *rows: str) -> Path:
    path.write_text(ROSTER_HEADER + "".join(row + "\n" for row in rows))
    return path


def vehicle_count(engine: Engine) -> int:
    with engine.connect() as connection:
        return int(connection.execute(text("SELECT count(*) FROM dim_vehicle")).scalar_one())


def test_seed_then_list(database_url: str, engine: Engine) -> None:
    env = cli_env(SMOOTHFLEET_DATABASE_URL=database_url)
    seeded = run_cli("seed", env=env)
    assert seeded.returncode == 0, seeded.stderr
    assert "100 vehicles" in seeded.stdout
    # the seed's RAV4s run rl_accel on the shipped policy, which the seed stores for them
    shipped = hashlib.sha256((BUNDLED_POLICIES / "rl_accel.npz").read_bytes()).hexdigest()
    assert f"rl_accel: policy {shipped[:12]} held" in seeded.stdout
    listed = run_cli("vehicles", "list", env=env)
    assert listed.returncode == 0
    assert "SF-100" in listed.stdout
    assert vehicle_count(engine) == 100


def test_import_with_a_bad_row_names_it_and_writes_nothing(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path
) -> None:
    roster = write_roster(
        tmp_path / "fleet.csv",
        "SF-201,JN8BT3BB3PW906499,Nissan,Rogue,2023,acc,I-24-WB,A,1,microaccel_acc,{}",
        "SF-202,JN8BT3BB3PW906498,Nissan,Rogue,2023,acc,I-24-WB,A,2,microaccel,{}",
    )
    result = run_cli(
        "vehicles", "import", str(roster), env=cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    )
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "fleet.csv row 3" in lines[0]
    assert "cannot drive actuation 'acc'" in lines[0]
    assert vehicle_count(seeded_engine) == 100


def test_a_roster_that_is_not_utf8_is_one_line_naming_it(tmp_path: Path) -> None:
    """It was 'unexpected UnicodeDecodeError', naming neither the file nor what to do."""
    roster = write_roster(
        tmp_path / "fleet.csv",
        "SF-201,JN8BT3BB3PW906499,Nissan,Rogue,2023,acc,I-24-WB,A,1,microaccel_acc,{}",
    )
    roster.write_bytes(roster.read_bytes().replace(b"Rogue", "Rogué".encode("latin-1")))
    with pytest.raises(RosterError, match=r"fleet.csv: not UTF-8 text \(invalid .*CSV UTF-8$"):
        parse_roster_csv(roster)


def test_roster_parameters_nested_past_the_json_parsers_depth_name_their_row(
    tmp_path: Path,
) -> None:
    """100,000 "[" escaped as a RecursionError ("unexpected RecursionError" from the CLI)."""
    nested = '"' + "[" * 100_000 + '"'
    roster = write_roster(
        tmp_path / "fleet.csv",
        f"SF-201,JN8BT3BB3PW906499,Nissan,Rogue,2023,acc,I-24-WB,A,1,microaccel_acc,{nested}",
    )
    with pytest.raises(RosterError, match=r"fleet.csv row 2: .*nested too deeply"):
        parse_roster_csv(roster)


def test_a_reimport_that_changes_a_cars_assignment_is_a_new_config_version(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path
) -> None:
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)

    def version_after_import(lane: int) -> int:
        row = f"SF-201,JN8BT3BB3PW906499,Nissan,Rogue,2023,acc,I-24-WB,A,{lane},microaccel_acc,{{}}"
        result = run_cli("vehicles", "import", str(write_roster(tmp_path / "f.csv", row)), env=env)
        assert result.returncode == 0, result.stderr
        with seeded_engine.connect() as connection:
            return int(
                connection.execute(
                    text("SELECT config_version FROM dim_vehicle WHERE vehicle_id = 'SF-201'")
                ).scalar_one()
            )

    assert version_after_import(1) == 1
    assert version_after_import(1) == 1  # the same row again: nothing for the car to pick up
    # another lane: before, the version stayed, so the status could not tell whether the car
    # had picked the change up
    assert version_after_import(2) == 2


def test_import_refused_by_the_database_is_one_transaction(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path
) -> None:
    # The second row reuses SF-001's VIN under a new id: the unique VIN refuses it, so the
    # first (valid) row must not stay behind either.
    with seeded_engine.connect() as connection:
        taken_vin = connection.execute(
            text("SELECT vin FROM dim_vehicle WHERE vehicle_id = 'SF-001'")
        ).scalar_one()
    roster = write_roster(
        tmp_path / "fleet.csv",
        "SF-201,JN8BT3BB3PW906499,Nissan,Rogue,2023,acc,I-24-WB,A,1,microaccel_acc,{}",
        f"SF-202,{taken_vin},Nissan,Rogue,2023,acc,I-24-WB,A,2,microaccel_acc,{{}}",
    )
    result = run_cli(
        "vehicles", "import", str(roster), env=cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    )
    assert result.returncode == 1
    assert len(result.stderr.strip().splitlines()) == 1
    assert f"Key (vin)=({taken_vin}) already exists" in result.stderr
    assert vehicle_count(seeded_engine) == 100


def test_tokens_are_printed_once_and_stored_hashed(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    result = run_cli("tokens", "create", "--role", "vehicle", "--vehicle", "SF-007", env=env)
    assert result.returncode == 0, result.stderr
    token = result.stdout.strip()
    assert token.startswith("sf_")
    assert len(token) > 40
    with seeded_engine.connect() as connection:
        stored = connection.execute(
            text("SELECT token_hash, kind, vehicle_id FROM api_token")
        ).one()
    assert tuple(stored) == (hashlib.sha256(token.encode()).hexdigest(), "vehicle", "SF-007")
    assert token not in stored[0]
    unknown = run_cli("tokens", "create", "--role", "vehicle", "--vehicle", "NOPE", env=env)
    assert unknown.returncode == 1
    assert unknown.stderr.strip() == "smoothfleet: error: tokens create: unknown vehicle NOPE"


@pytest.mark.parametrize(
    ("env", "expected"),
    [
        (
            {"SMOOTHFLEET_DATABASE_URL": "postgresql://nobody@127.0.0.1:1/none"},
            "cannot reach the database at 127.0.0.1:1/none",
        ),
        ({"SMOOTHFLEET_DATABASE_URL": "mysql://x@y/z"}, "SMOOTHFLEET_DATABASE_URL: must be"),
        ({"SMOOTHFLEET_PORT": "eighty"}, "SMOOTHFLEET_PORT:"),
        # passes its lower bound (ge=0) unless the settings refuse infinity as such
        (
            {"SMOOTHFLEET_PING_MAX_FUTURE_S": "inf"},
            "SMOOTHFLEET_PING_MAX_FUTURE_S: Input should be a finite number",
        ),
        # each valid alone: every plan would expire two minutes before the next
        (
            {"SMOOTHFLEET_PLANNER_PERIOD_S": "300", "SMOOTHFLEET_PLAN_VALID_FOR_S": "180"},
            "SMOOTHFLEET_PLAN_VALID_FOR_S 180 must be longer than SMOOTHFLEET_PLANNER_PERIOD_S 300",
        ),
    ],
)
def test_a_wrong_setting_is_one_line_naming_it(env: dict[str, str], expected: str) -> None:
    result = run_cli("seed", env=cli_env(**env))
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert expected in lines[0]


def test_a_database_without_the_schema_is_one_line_naming_the_fix(pg_server: str) -> None:
    """The error types are imported only once a command fails (smoothfleet/cli/main.py): the
    missing schema is still recognised, not shown as an unexpected error."""
    with database_from_template(pg_server, "template0") as url:
        result = run_cli("vehicles", "list", env=cli_env(SMOOTHFLEET_DATABASE_URL=url))
    assert result.returncode == 1
    assert result.stderr == (
        "smoothfleet: error: the database has no smoothfleet schema yet: run `smoothfleet db "
        "upgrade`\n"
    )


def test_a_taken_port_is_one_line(database_url: str) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = run_cli(
            "serve", "--port", str(port), env=cli_env(SMOOTHFLEET_DATABASE_URL=database_url)
        )
    assert result.returncode == 1
    assert result.stderr.strip() == (
        f"smoothfleet: error: port {port} on 127.0.0.1 is already in use "
        "(choose another with --port or SMOOTHFLEET_PORT)"
    )


def postgres_processes(pgdata: Path) -> list[psutil.Process]:
    found = []
    for process in psutil.process_iter(["name", "cmdline"]):
        cmdline = process.info.get("cmdline") or []
        if process.info.get("name") == "postgres" and str(pgdata) in " ".join(cmdline):
            found.append(process)
    return found


@pytest.mark.slow
def test_embedded_database_serves_and_stops_on_sigterm(tmp_path: Path) -> None:
    data_dir = tmp_path / "data"
    port = free_port()
    env = cli_env(SMOOTHFLEET_DATA_DIR=str(data_dir), SMOOTHFLEET_PORT=str(port))
    log = (tmp_path / "serve.log").open("w")
    server = subprocess.Popen(
        [*smoothfleet_command(), "serve"], env=env, stdout=log, stderr=subprocess.STDOUT
    )
    try:
        base = f"http://127.0.0.1:{port}"
        wait_until_ready(base)
        assert httpx.get(f"{base}/healthz").json() == {"status": "ok"}
        assert httpx.get(f"{base}/readyz").json()["status"] == "ready"
        assert "python_gc_objects_collected_total" in httpx.get(f"{base}/metrics").text
        assert postgres_processes(data_dir / "pgdata")
    finally:
        server.send_signal(signal.SIGTERM)
        server.wait(timeout=60)
        log.close()
    assert server.returncode == 128 + signal.SIGTERM, (tmp_path / "serve.log").read_text()
    deadline = time.monotonic() + 20
    while postgres_processes(data_dir / "pgdata") and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not postgres_processes(data_dir / "pgdata"), "embedded PostgreSQL left running"
    # The data directory is kept between runs: a second command finds the schema in place.
    again = run_cli("db", "url", env=env)
    assert again.returncode == 0
    assert "/smoothfleet" in again.stdout
    assert (data_dir / "pgdata" / "PG_VERSION").exists()


def test_a_damaged_handle_list_of_the_embedded_server_is_healed(tmp_path: Path) -> None:
    env = cli_env(SMOOTHFLEET_DATA_DIR=str(tmp_path / "data"))
    first = run_cli("db", "url", env=env)
    assert first.returncode == 0, first.stderr
    # What a process killed while the wheel rewrote its handle list leaves behind.
    (tmp_path / "data" / "pgdata" / ".handle_pids.json").write_text("")
    again = run_cli("db", "url", env=env)
    assert again.returncode == 0, again.stderr
    assert "/smoothfleet" in again.stdout


def test_a_backup_of_the_embedded_database_is_whole_and_restores(
    tmp_path: Path, pg_server: str
) -> None:
    """operations.md had `pg_dump "$(smoothfleet db url)"`, whose server had stopped by the
    time pg_dump connected: no backup at all (ops audit). `db dump` holds it while pg_dump
    runs, and the file restores into an empty database, as operations.md says to."""
    env = cli_env(SMOOTHFLEET_DATA_DIR=str(tmp_path / "data"))
    assert run_cli("db", "upgrade", env=env).returncode == 0
    assert run_cli("tokens", "create", "--role", "viewer", env=env).returncode == 0
    backup = tmp_path / "backups" / "smoothfleet.dump"
    backup.parent.mkdir()
    backup.write_bytes(b"last night's")

    dumped = run_cli("db", "dump", str(backup), env=env)

    assert dumped.returncode == 0, dumped.stderr
    assert f"{backup}: " in dumped.stdout.replace("\n", "")  # (rich wraps long lines)
    assert backup.read_bytes()[:5] == b"PGDMP"
    assert not list(backup.parent.glob("*partial*"))
    name = f"restored_{int(time.time() * 1000)}"
    admin_execute(pg_server, sql.SQL("CREATE DATABASE {}").format(sql.Identifier(name)))
    restored = embedded_url(pg_server, name)
    try:
        # operations.md said `createdb NEW && pg_restore --dbname=NEW FILE`: Debian 12's
        # pg_restore refuses the embedded pg_dump's format, and createdb finds no embedded
        # server running; `db restore` holds it and runs the newest pg_restore at hand
        into_new = cli_env(SMOOTHFLEET_DATABASE_URL=restored)
        answer = run_cli("db", "restore", str(backup), env=into_new)
        assert answer.returncode == 0, answer.stderr
        assert f"database at {head_revision()}" in answer.stdout
        # over a database that holds tables, nothing is restored
        again = run_cli("db", "restore", str(backup), env=into_new)
        assert again.returncode == 1
        assert "restore into an empty one" in again.stderr
        engine = make_sync_engine(restored)
        with engine.connect() as connection:
            assert current_revision(connection) == head_revision()
            tokens = connection.execute(text("SELECT role FROM api_token")).scalars().all()
        engine.dispose()
        assert tokens == ["viewer"]
        # a database downgraded to base keeps alembic_version: the refusal says so
        assert run_cli("db", "downgrade", "base", "--yes", env=into_new).returncode == 0
        emptied = run_cli("db", "restore", str(backup), env=into_new)
        assert emptied.returncode == 1
        assert "DROP TABLE alembic_version" in emptied.stderr.replace("\n", "")
    finally:
        admin_execute(
            pg_server,
            sql.SQL("DROP DATABASE IF EXISTS {} WITH (FORCE)").format(sql.Identifier(name)),
        )


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (("tokens", "revoke", "--id", "99999999999999999999"), "--id"),
        (("tokens", "create", "--role", "admin", "--name", "bad\udcffname"), "--name"),
        (("tokens", "create", "--role", "vehicle", "--vehicle", "SF-\udcff"), "--vehicle"),
        (("tokens", "revoke", "--vehicle", "SF-\x01\udcff"), "--vehicle"),
    ],
    ids=["id-beyond-bigint", "name-not-utf8", "vehicle-not-utf8", "revoke-vehicle-not-utf8"],
)
def test_token_options_the_database_cannot_hold_are_refused_naming_the_option(
    args: tuple[str, ...], option: str, database_url: str
) -> None:
    """A bigint overflow and bytes that are no UTF-8 (a lone surrogate to Python) reached the
    database: "unexpected DataError ... [SQL: UPDATE api_token ...]", "unexpected
    UnicodeEncodeError"."""
    result = run_cli(*args, env=cli_env(SMOOTHFLEET_DATABASE_URL=database_url))
    assert result.returncode == 2, result.stderr
    assert f"Invalid value for '{option}'" in result.stderr
    assert "unexpected" not in result.stderr


PASSWORD = "S3cretPw"


def tool_on_path(bin_path: Path, name: str, body: str) -> None:
    """A stand-in for a PostgreSQL client on PATH: answers `--version` as release 99 (newer
    than any, so `db dump` picks it), otherwise runs `body` (sh)."""
    tool = bin_path / name
    tool.write_text(
        "#!/bin/sh\n"
        f'if [ "$1" = --version ]; then echo "{name} (PostgreSQL) 99.0"; exit 0; fi\n' + body
    )
    tool.chmod(0o755)


def with_password(url: str) -> str:
    from sqlalchemy.engine import make_url

    return make_url(url).set(password=PASSWORD).render_as_string(hide_password=False)


@pytest.mark.parametrize("command", ["psql", "dump"])
def test_psql_and_dump_get_the_password_from_their_environment_not_their_command_line(
    command: str, database_url: str, tmp_path: Path
) -> None:
    """Both put the whole URL on the child's command line, where `ps` shows every user of
    the host the production database's password (a nightly backup's, say)."""
    seen = tmp_path / "seen"
    tool_on_path(
        tmp_path,
        "pg_dump" if command == "dump" else "psql",
        f'echo "argv: $*" > {seen}; echo "password: $PGPASSWORD; zone: $PGTZ" >> {seen}\n'
        'for arg in "$@"; do case "$arg" in --file=*) echo dump > "${arg#--file=}";; esac; done\n',
    )
    env = cli_env(
        SMOOTHFLEET_DATABASE_URL=with_password(database_url),
        PATH=f"{tmp_path}:{cli_env()['PATH']}",
    )
    args = ["db", "psql"] if command == "psql" else ["db", "dump", str(tmp_path / "x.dump")]

    result = run_cli(*args, env=env)

    assert result.returncode == 0, result.stderr
    argv, environment = seen.read_text().splitlines()
    assert PASSWORD not in argv
    assert environment == f"password: {PASSWORD}; zone: UTC"


def test_two_dumps_to_one_file_never_write_into_one_file(database_url: str, tmp_path: Path) -> None:
    """Both wrote FILE.partial: the second truncated it while the first wrote, the first
    renamed it into place as a good backup (the second's start, its own end), and the second
    failed. Each writes its own file now, and FILE is one whole dump."""
    tool_on_path(
        tmp_path,
        "pg_dump",
        'for arg in "$@"; do case "$arg" in --file=*) out="${arg#--file=}";; esac; done\n'
        'echo "begins $$" > "$out"; sleep 3; echo "ends $$" >> "$out"\n',
    )
    env = cli_env(SMOOTHFLEET_DATABASE_URL=database_url, PATH=f"{tmp_path}:{cli_env()['PATH']}")
    backup = tmp_path / "nightly.dump"
    command = [*smoothfleet_command(), "db", "dump", str(backup)]
    first = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    time.sleep(1.5)
    second = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    outcomes = [process.communicate(timeout=120) for process in (first, second)]

    assert [first.returncode, second.returncode] == [0, 0], outcomes
    began, ended = backup.read_text().split()[1::2]
    assert began == ended
    assert not list(tmp_path.glob("*partial*"))


@pytest.mark.slow
def test_the_embedded_server_still_stops_after_a_holder_was_killed(tmp_path: Path) -> None:
    """A SIGKILLed holder never leaves the handle list itself; the next command drops it."""
    data_dir = tmp_path / "data"
    env = cli_env(SMOOTHFLEET_DATA_DIR=str(data_dir))
    holder = subprocess.Popen(
        [*smoothfleet_command(), "db", "psql"],
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    handles = data_dir / "pgdata" / ".handle_pids.json"
    deadline = time.monotonic() + 60
    while not (handles.exists() and str(holder.pid) in handles.read_text()):
        assert time.monotonic() < deadline, "the holder never joined the server"
        time.sleep(0.2)
    psql = psutil.Process(holder.pid).children(recursive=True)
    holder.kill()
    holder.wait(timeout=10)
    assert holder.stdin is not None
    holder.stdin.close()  # its psql, orphaned, reads end-of-input and leaves
    psutil.wait_procs(psql, timeout=10)

    again = run_cli("db", "url", env=env)

    assert again.returncode == 0, again.stderr
    assert handles.read_text() == "[]"
    deadline = time.monotonic() + 20
    while postgres_processes(data_dir / "pgdata") and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not postgres_processes(data_dir / "pgdata"), "embedded PostgreSQL left running"


def test_db_downgrade_upgrade_and_maintain_from_the_command_line(
    database_url: str, engine: Engine
) -> None:
    """The operator's schema commands (docs/operations.md): down to base and back to head,
    then the ping partitions' housekeeping, which a second run finds done."""
    env = cli_env(SMOOTHFLEET_DATABASE_URL=database_url)
    # with no terminal to ask on, a downgrade says what it would undo and changes nothing
    asked = run_cli("db", "downgrade", "base", env=env, stdin="")
    assert asked.returncode == 1
    assert f"db downgrade base undoes {int(head_revision())} migration(s)" in asked.stderr
    assert "0012  A vehicle's assignments over time" in asked.stderr
    assert "nothing was changed: pass --yes to go on" in asked.stderr
    with engine.connect() as connection:
        assert current_revision(connection) == head_revision()
    # one step down: "-1" was refused as "No such option", and the line said "database at -1"
    one_step = run_cli("db", "downgrade", "-1", "--yes", env=env)
    assert one_step.returncode == 0, one_step.stderr
    with engine.connect() as connection:
        below_head = current_revision(connection)
    assert below_head is not None
    assert below_head != head_revision()
    assert f"database at {below_head}" in one_step.stdout
    # "-1" again, from below head: it was listed from the newest migration (nothing undone),
    # so it went ahead unasked and dropped a column; it is counted from the database now
    asked = run_cli("db", "downgrade", "-1", env=env, stdin="")
    assert asked.returncode == 1
    assert "undoes 1 migration(s)" in asked.stderr
    assert f"  {below_head}  " in asked.stderr
    with engine.connect() as connection:
        assert current_revision(connection) == below_head
    below_base = run_cli("db", "downgrade", "base-1", "--yes", env=env)
    assert below_base.returncode != 0
    assert "no migration is below 'base'" in below_base.stderr  # was an AttributeError
    too_far = run_cli("db", "downgrade", "-99", "--yes", env=env)
    assert too_far.returncode != 0
    assert f"{below_head} is only {int(below_head)} step(s) above base, not 99" in too_far.stderr
    down = run_cli("db", "downgrade", "base", "--yes", env=env)
    assert down.returncode == 0, down.stderr
    assert "database at base" in down.stdout
    with engine.connect() as connection:
        assert connection.execute(text("SELECT to_regclass('dim_vehicle')")).scalar() is None
    up = run_cli("db", "upgrade", env=env)
    assert up.returncode == 0, up.stderr
    assert "database at head" in up.stdout
    with engine.connect() as connection:
        assert current_revision(connection) == head_revision()
    first = run_cli("db", "maintain", env=env)
    assert first.returncode == 0, first.stderr
    assert "dropped (retention 90 days)" in first.stdout
    again = run_cli("db", "maintain", env=env)
    assert again.returncode == 0, again.stderr
    assert "ping partitions: 0 created, 0 dropped" in again.stdout
    unknown = run_cli("db", "upgrade", "no_such_revision", env=env)
    assert unknown.returncode != 0
    assert "no migration revision 'no_such_revision'" in unknown.stderr
    assert "the revisions: base, 0001," in unknown.stderr
    assert "Traceback" not in unknown.stderr


@pytest.mark.parametrize(
    ("model", "route", "refusal"),
    [
        ("Ro\x00gue", "A", r"row 2: model: .*NUL"),
        ("Rogue", "R" * 65, r"row 2: route: .*at most 64 characters"),
    ],
    ids=["nul", "long-route"],
)
def test_roster_text_is_refused_by_row_as_the_api_would_refuse_it(
    tmp_path: Path, model: str, route: str, refusal: str
) -> None:
    """A NUL reached the database as a raw error (the whole statement, no row); a route the
    assignment API refuses (over 64 characters) was imported, and the car's next lane change
    was then refused for a route the operator never typed."""
    roster = write_roster(
        tmp_path / "fleet.csv",
        f"SF-201,JN8BT3BB3PW906499,Nissan,{model},2023,acc,I-24-WB,{route},1,microaccel_acc,{{}}",
    )
    with pytest.raises(RosterError, match=refusal):
        parse_roster_csv(roster)


def test_a_bad_row_after_blank_lines_names_its_line_too(tmp_path: Path) -> None:
    """Rows count records, which a blank line or a quoted field over two lines sets apart from
    the lines an editor shows: the line is named where they differ."""
    roster = write_roster(
        tmp_path / "fleet.csv",
        "SF-201,JN8BT3BB3PW906499,Nissan,Rogue,2023,acc,I-24-WB,A,1,microaccel_acc,{}",
        "",
        "",
        "SF-202,JN8BT3BB3PW906498,Nissan,Rogue,2023,acc,I-24-WB,A,0,microaccel_acc,{}",
    )
    with pytest.raises(RosterError, match=r"fleet.csv row 3 \(line 5\): assigned_lane: "):
        parse_roster_csv(roster)
