"""`smoothfleet users add|list` and `smoothfleet analytics list|export` in a subprocess."""

from __future__ import annotations

import csv
import subprocess
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
from sqlalchemy import Engine, text

from app.users.service import verify_password
from tests.support.fleet import ping, post_pings
from tests.support.servers import cli_env, live_server, run_cli, smoothfleet_command
from tests.support.tokens import issue


def add_user(database_url: str, *args: str, password: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*smoothfleet_command(), "users", "add", *args, "--password-stdin"],
        input=password + "\n",
        env=cli_env(SMOOTHFLEET_DATABASE_URL=database_url),
        capture_output=True,
        text=True,
        timeout=120,
    )


def stored_user(engine: Engine, username: str) -> tuple[str, str]:
    with engine.connect() as connection:
        row = connection.execute(
            text("SELECT role, password_hash FROM ops_user WHERE username = :u"), {"u": username}
        ).one()
    return str(row[0]), str(row[1])


def test_users_add_with_no_terminal_and_no_password_stdin_says_so(database_url: str) -> None:
    """It printed "password:", read end-of-input and exited 130 without a word."""
    result = run_cli(
        "users",
        "add",
        "ops",
        "--role",
        "operator",
        env=cli_env(SMOOTHFLEET_DATABASE_URL=database_url),
        stdin="",
    )
    assert result.returncode == 1
    assert "no terminal to ask the password on: pipe it in with --password-stdin" in (result.stderr)


def test_users_add_stores_a_salted_scrypt_hash_and_can_reset_it(
    database_url: str, engine: Engine
) -> None:
    created = add_user(database_url, "maria", "--role", "operator", password="correct horse")
    assert created.returncode == 0, created.stderr
    assert "user maria created with role operator" in created.stdout
    role, password_hash = stored_user(engine, "maria")
    assert role == "operator"
    assert password_hash.startswith("scrypt$16384$8$1$")
    assert "correct horse" not in password_hash
    assert verify_password("correct horse", password_hash)
    assert not verify_password("correct horsE", password_hash)

    reset = add_user(database_url, "maria", "--role", "viewer", password="battery staple")
    assert "user maria updated with role viewer" in reset.stdout
    role, new_hash = stored_user(engine, "maria")
    assert role == "viewer"
    assert verify_password("battery staple", new_hash)
    # A fresh salt each time: the same password never gives the same hash.
    again = add_user(database_url, "maria", "--role", "viewer", password="battery staple")
    assert again.returncode == 0
    assert stored_user(engine, "maria")[1] != new_hash

    listed = run_cli("users", "list", env=cli_env(SMOOTHFLEET_DATABASE_URL=database_url))
    assert "maria" in listed.stdout
    assert "viewer" in listed.stdout


def test_users_add_refuses_a_short_password_in_one_line(database_url: str, engine: Engine) -> None:
    result = add_user(database_url, "bob", "--role", "admin", password="short")
    assert result.returncode == 1
    assert result.stderr.strip() == (
        "smoothfleet: error: users add: password: at least 10 characters"
    )
    with engine.connect() as connection:
        assert connection.execute(text("SELECT count(*) FROM ops_user")).scalar_one() == 0


def test_users_add_refuses_an_unknown_role(database_url: str) -> None:
    result = add_user(database_url, "bob", "--role", "root", password="long enough pw")
    assert result.returncode == 2
    assert "'root' is not one of 'viewer', 'operator', 'admin'" in result.stderr


def test_analytics_list_names_every_view(database_url: str) -> None:
    result = run_cli("analytics", "list", env=cli_env(SMOOTHFLEET_DATABASE_URL=database_url))
    assert result.returncode == 0
    for name in ("engagement_daily", "edie_boxes", "plan_adherence", "inrix_latency"):
        assert name in result.stdout


def test_analytics_export_writes_a_view_as_csv(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path
) -> None:
    # SF-007 drives 5 pings, 2 engaged: engagement share 0.4.
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(minutes=10)
    pings = [
        ping(
            "SF-007",
            start + timedelta(seconds=i),
            3000.0 + 25.0 * i,
            25.0,
            controller_engaged=i < 2,
        )
        for i in range(5)
    ]
    with live_server(seeded_database_url) as base, httpx.Client(base_url=base) as client:
        post_pings(client, issue(seeded_engine, "admin"), pings)
    output = tmp_path / "engagement.csv"
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)

    result = run_cli(
        "analytics",
        "export",
        "engagement_daily",
        "--vehicle",
        "SF-007",
        "-o",
        str(output),
        env=env,
    )

    assert result.returncode == 0, result.stderr
    assert "1 row(s) of analytics.engagement_daily" in result.stderr
    rows = list(csv.DictReader(output.read_text().splitlines()))
    assert len(rows) == 1
    assert rows[0]["vehicle_id"] == "SF-007"
    assert rows[0]["day"] == start.date().isoformat()
    assert (rows[0]["pings"], rows[0]["engaged_pings"]) == ("5", "2")
    assert float(rows[0]["engagement_share"]) == 0.4

    later = run_cli(
        "analytics",
        "export",
        "engagement_daily",
        "--since",
        (start + timedelta(days=1)).date().isoformat(),
        env=env,
    )
    assert later.returncode == 0
    assert later.stdout.strip().splitlines() == [
        "vehicle_id,day,pings,engaged_pings,acc_engaged_pings,engagement_share,acc_engaged_share"
    ]


def test_analytics_export_names_the_views_when_one_is_unknown(database_url: str) -> None:
    env = cli_env(SMOOTHFLEET_DATABASE_URL=database_url)
    result = run_cli("analytics", "export", "speeds", env=env)
    assert result.returncode == 1
    assert result.stderr.startswith(
        "smoothfleet: error: analytics export: unknown analytics view 'speeds'; choose one of:"
    )
    bad_time = run_cli("analytics", "export", "edie_boxes", "--since", "yesterday", env=env)
    assert bad_time.returncode == 1
    assert "--since: not an ISO 8601 date or time: 'yesterday'" in bad_time.stderr
    too_early = run_cli(
        "analytics", "export", "edie_boxes", "--since", "0001-01-01T00:00:00+14:00", env=env
    )
    assert too_early.returncode == 1
    assert "--since: '0001-01-01T00:00:00+14:00' is out of range once read in UTC" in (
        too_early.stderr
    )
    reversed_window = run_cli(
        "analytics",
        "export",
        "engagement_daily",
        "--since",
        "2026-02-01",
        "--until",
        "2026-01-01",
        env=env,
    )
    assert reversed_window.returncode == 1
    assert "the window ends before it starts: until 2026-01-01T00:00:00+00:00 is before since" in (
        reversed_window.stderr
    )
    # a misspelt car read as a car with no data: an empty file and exit 0
    unknown_car = run_cli(
        "analytics", "export", "engagement_daily", "--vehicle", "SF-NOPE", env=env
    )
    assert unknown_car.returncode == 1
    assert "analytics export: no vehicle 'SF-NOPE' on the roster" in unknown_car.stderr


def test_a_refused_export_leaves_the_earlier_file_whole(database_url: str, tmp_path: Path) -> None:
    """The file used to be opened, and so emptied, before the request was checked."""
    env = cli_env(SMOOTHFLEET_DATABASE_URL=database_url)
    output = tmp_path / "hourly.csv"
    assert (
        run_cli("analytics", "export", "fleet_ping_hourly", "-o", str(output), env=env).returncode
        == 0
    )
    earlier = output.read_bytes()
    assert earlier.startswith(b"hour,")

    refused = run_cli(
        "analytics",
        "export",
        "fleet_ping_hourly",
        "--vehicle",
        "SF-001",
        "-o",
        str(output),
        env=env,
    )

    assert refused.returncode == 1
    assert "analytics view fleet_ping_hourly has no vehicle_id column" in refused.stderr
    assert output.read_bytes() == earlier
