"""The docker-compose stack: the file is checked, and its services' commands run together.

No Docker engine runs here, so `test_the_services_work_together` starts the API and the planner
exactly as their compose services do (same `smoothfleet` command, same environment, but the
database URL pointing at the test's PostgreSQL and the API on a free local port) as separate
processes against one database, and checks that a feed snapshot and a car's pings posted to the
API become a plan published by the separate planner process.
"""

from __future__ import annotations

import re
import subprocess
import time
import tomllib
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import httpx
import pytest
from psycopg import sql
from sqlalchemy import text

from app.core.db import make_sync_engine
from app.core.embedded import database_url as url_of
from tests.dashboards.support import PASSWORDS, log_in
from tests.deploy.compose import ComposeError, load, service_environment
from tests.planner.facts import INRIX_CODES, standing_slowdown
from tests.support.databases import admin_execute
from tests.support.fleet import drive
from tests.support.servers import (
    cli_env,
    free_port,
    run_cli,
    smoothfleet_command,
    stop_gracefully,
    wait_until_ready,
)
from tests.support.tokens import bearer, issue

SECRETS = {"POSTGRES_PASSWORD": "compose-test-password", "SMOOTHFLEET_SECRET_KEY": "x" * 48}
MPH = 0.44704


@pytest.fixture(scope="module")
def compose() -> dict[str, Any]:
    return load({**SECRETS, "SMOOTHFLEET_PLANNER_PERIOD_S": "2"})


def test_postgres_is_the_official_image_pinned_with_volume_and_healthcheck(
    compose: dict[str, Any],
) -> None:
    db = compose["services"]["db"]
    assert re.fullmatch(r"postgres:\d+", db["image"]), db["image"]
    assert any(volume.endswith(":/var/lib/postgresql/data") for volume in db["volumes"])
    assert "pg_isready" in " ".join(db["healthcheck"]["test"])
    assert compose["services"]["api"]["depends_on"]["db"]["condition"] == "service_healthy"
    assert compose["services"]["planner"]["depends_on"]["api"]["condition"] == "service_healthy"


def test_the_image_is_built_from_every_package_the_project_installs() -> None:
    """The Dockerfile copied neither `smoothfleet` (the CLI its ENTRYPOINT runs) nor
    `contract` (what server and car share), so the image's wheel lacked both and its
    `smoothfleet` command could import nothing."""
    root = Path(__file__).resolve().parents[2]
    found = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]
    packages = {pattern.rstrip("*") for pattern in found["packages"]["find"]["include"]}
    dockerfile = (root / "Dockerfile").read_text()
    copied = set(re.findall(r"^COPY (\S+) \./\1$", dockerfile, flags=re.MULTILINE))
    assert packages <= copied, f"not copied into the image: {sorted(packages - copied)}"


def test_required_secrets_fail_fast() -> None:
    with pytest.raises(ComposeError, match="POSTGRES_PASSWORD"):
        load({"SMOOTHFLEET_SECRET_KEY": "x" * 48})
    with pytest.raises(ComposeError, match="SMOOTHFLEET_SECRET_KEY"):
        load({"POSTGRES_PASSWORD": "pw"})


def test_services_share_the_database_and_run_in_production(compose: dict[str, Any]) -> None:
    api = service_environment(compose["services"]["api"])
    planner = service_environment(compose["services"]["planner"])
    expected = "postgresql://smoothfleet:compose-test-password@db:5432/smoothfleet"
    assert api["SMOOTHFLEET_DATABASE_URL"] == planner["SMOOTHFLEET_DATABASE_URL"] == expected
    assert api["SMOOTHFLEET_ENVIRONMENT"] == planner["SMOOTHFLEET_ENVIRONMENT"] == "production"
    assert compose["services"]["api"]["command"] == ["serve", "--workers", "2", "--no-planner"]
    assert compose["services"]["planner"]["command"] == ["planner", "run"]
    assert compose["services"]["fleet"]["command"] == [
        "sim",
        "fleet",
        "--server",
        "http://api:8000",
    ]
    assert compose["services"]["fleet"]["profiles"] == ["fleet"]
    # the poller carries both INRIX settings (compose passes on only the variables it lists)
    inrix = service_environment(compose["services"]["inrix"])
    assert compose["services"]["inrix"]["command"] == ["inrix", "poll"]
    assert compose["services"]["inrix"]["profiles"] == ["inrix"]
    assert {"SMOOTHFLEET_INRIX_URL", "SMOOTHFLEET_INRIX_KEY"} <= inrix.keys()
    assert inrix["SMOOTHFLEET_DATABASE_URL"] == expected


@pytest.mark.parametrize("service", ["api", "planner", "inrix", "fleet"])
def test_every_service_command_is_a_real_cli_command(compose: dict[str, Any], service: str) -> None:
    result = run_cli(*compose["services"][service]["command"], "--help", env=cli_env())
    assert result.returncode == 0, result.stderr


def test_a_placeholder_secret_in_production_stops_the_api_with_one_line(
    compose: dict[str, Any], database_url: str
) -> None:
    environment = service_environment(compose["services"]["api"])
    environment |= {
        "SMOOTHFLEET_DATABASE_URL": database_url,
        "SMOOTHFLEET_SECRET_KEY": "change-me",
        "SMOOTHFLEET_PORT": str(free_port()),
    }
    result = run_cli(*compose["services"]["api"]["command"], env=cli_env(**environment))
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "SMOOTHFLEET_SECRET_KEY" in lines[0]


@pytest.fixture
def empty_database(pg_server: str) -> Iterator[str]:
    """A database with no schema at all: the API service must migrate it itself."""
    name = f"compose_{int(time.time() * 1000)}"
    admin_execute(pg_server, sql.SQL("CREATE DATABASE {}").format(sql.Identifier(name)))
    yield url_of(pg_server, name)
    admin_execute(
        pg_server, sql.SQL("DROP DATABASE IF EXISTS {} WITH (FORCE)").format(sql.Identifier(name))
    )


def start(
    compose: dict[str, Any], service: str, database: str, log: Path, **extra: str
) -> subprocess.Popen[bytes]:
    environment = service_environment(compose["services"][service])
    environment |= {"SMOOTHFLEET_DATABASE_URL": database, **extra}
    with log.open("w") as output:  # the child keeps its own copy of the descriptor
        return subprocess.Popen(
            [*smoothfleet_command(), *compose["services"][service]["command"]],
            env=cli_env(**environment),
            stdout=output,
            stderr=subprocess.STDOUT,
        )


def provider_snapshot(measured_at: datetime) -> dict[str, Any]:
    stamp = measured_at.strftime("%Y-%m-%dT%H:%M:%S.000Z")
    return {
        "docType": "GetSegmentSpeed",
        "result": {
            "segmentspeeds": [
                {
                    "timestamp": stamp,
                    "segments": [
                        {"code": code, "type": "XDS", "speed": round(speed / MPH), "score": 30}
                        for code, speed in zip(INRIX_CODES, standing_slowdown(), strict=True)
                    ],
                }
            ]
        },
    }


@pytest.fixture
def seeded_api(compose: dict[str, Any], empty_database: str, tmp_path: Path) -> Iterator[str]:
    """The api service's command on an empty database (it migrates it), seeded the way
    operators do (`docker compose run api seed`); yields its base URL."""
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    api = start(
        compose,
        "api",
        empty_database,
        tmp_path / "api.log",
        SMOOTHFLEET_HOST="127.0.0.1",
        SMOOTHFLEET_PORT=str(port),
    )
    try:
        wait_until_ready(base, timeout_s=120)
        seeded = run_cli("seed", env=cli_env(SMOOTHFLEET_DATABASE_URL=empty_database))
        assert seeded.returncode == 0, seeded.stderr
        yield base
    finally:
        stop_gracefully(api, tmp_path / "api.log")


@pytest.mark.slow
def test_the_services_work_together(
    compose: dict[str, Any], empty_database: str, seeded_api: str, tmp_path: Path
) -> None:
    base = seeded_api
    planner: subprocess.Popen[bytes] | None = None
    try:
        engine = make_sync_engine(empty_database)
        feed, car = issue(engine, "feed"), issue(engine, "vehicle", "SF-002")
        now = datetime.now(UTC).replace(second=0, microsecond=0)
        with httpx.Client(base_url=base, timeout=30) as client:
            for minutes_ago in range(6, 2, -1):
                snapshot = provider_snapshot(now - timedelta(minutes=minutes_ago))
                posted = client.post("/api/v1/feeds/inrix", json=snapshot, headers=bearer(feed))
                assert posted.status_code == 200, posted.text
            pings = drive("SF-002", datetime.now(UTC) - timedelta(seconds=30), 8400, 5.0, 30)
            stored = client.post("/api/v1/pings", json={"pings": pings}, headers=bearer(car))
            assert stored.json()["accepted"] == 30, stored.text
            planner = start(compose, "planner", empty_database, tmp_path / "planner.log")
            deadline = time.monotonic() + 120
            plan = client.get("/api/v1/vehicles/SF-002/plan", headers=bearer(car))
            while plan.status_code != 200 and time.monotonic() < deadline:
                assert planner.poll() is None, (tmp_path / "planner.log").read_text()
                time.sleep(0.5)
                plan = client.get("/api/v1/vehicles/SF-002/plan", headers=bearer(car))
        assert plan.status_code == 200, (tmp_path / "planner.log").read_text()
        body = plan.json()
        assert [lane["lane"] for lane in body["lanes"]] == [2]
        assert body["inputs"]["vehicles"] == 1
        with engine.connect() as connection:
            revision = connection.execute(text("SELECT version_num FROM alembic_version"))
            assert revision.scalar_one()
        engine.dispose()
    finally:
        if planner is not None:
            stop_gracefully(planner, tmp_path / "planner.log")


@pytest.mark.slow
def test_the_fleet_profile_drives_cars_against_the_api(
    compose: dict[str, Any], empty_database: str, seeded_api: str, tmp_path: Path
) -> None:
    fleet = compose["services"]["fleet"]
    command = [seeded_api if part == "http://api:8000" else part for part in fleet["command"]]
    environment = service_environment(fleet) | {
        "SMOOTHFLEET_DATABASE_URL": empty_database,
        "SMOOTHFLEET_DATA_DIR": str(tmp_path / "fleet"),
    }
    result = run_cli(
        *command, "--duration", "20", "--vehicles", "4", env=cli_env(**environment), timeout=300
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "from 4 vehicles" in result.stdout, result.stdout
    engine = make_sync_engine(empty_database)
    with engine.connect() as connection:
        vehicles, snapshots = connection.execute(
            text(
                "SELECT (SELECT count(DISTINCT vehicle_id) FROM fact_vehicle_ping), "
                "(SELECT count(DISTINCT measured_at) FROM fact_inrix_estimate)"
            )
        ).one()
    engine.dispose()
    assert vehicles == 4
    assert snapshots >= 15  # the feed's backfill of the last quarter hour


@pytest.mark.slow
def test_the_feeds_page_counts_every_workers_rejections(
    compose: dict[str, Any], empty_database: str, seeded_api: str
) -> None:
    # The api service runs two workers; each request below comes on a new connection, so both
    # take some. The operator's count must not depend on which worker renders the page.
    engine = make_sync_engine(empty_database)
    car = issue(engine, "vehicle", "SF-003")
    engine.dispose()
    added = run_cli(
        "users", "add", "viewer", "--role", "viewer", "--password-stdin",
        env=cli_env(SMOOTHFLEET_DATABASE_URL=empty_database),
        stdin=PASSWORDS["viewer"] + "\n",
    )  # fmt: skip
    assert added.returncode == 0, added.stderr
    first_ts = datetime.now(UTC) - timedelta(seconds=60)
    for second, bad in enumerate(drive("SF-003", first_ts, 8400, 95.0, 20)):  # > 90 m/s
        with httpx.Client(base_url=seeded_api, timeout=30) as client:
            # a batch of one: a lone ping that fails validation is a 422, a batch's item is
            # rejected and counted
            answer = client.post("/api/v1/pings", json={"pings": [bad]}, headers=bearer(car))
            assert answer.status_code == 200, (second, answer.text)
            assert answer.json()["rejected"], (second, answer.text)
    shown = set()
    for _ in range(6):
        with httpx.Client(base_url=seeded_api, timeout=30) as client:
            assert log_in(client, "viewer", PASSWORDS["viewer"]).status_code == 303
            page = client.get("/feeds").text
            found = re.search(r'data-field="pings-rejected">(\d+)<', page)
            assert found, page
            shown.add(int(found.group(1)))
    assert shown == {20}
