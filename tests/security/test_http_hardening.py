"""Security headers, per-token and per-address rate limits, local API docs, no secrets in logs."""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import pytest
from sqlalchemy import Engine

from tests.dashboards.support import PASSWORDS, add_users, log_in
from tests.support.api import ping
from tests.support.servers import (
    cli_env,
    free_port,
    live_server,
    smoothfleet_command,
    stop_gracefully,
    wait_until_ready,
)
from tests.support.tokens import bearer, issue


@pytest.fixture
def api(seeded_database_url: str) -> Iterator[httpx.Client]:
    settings = {
        "rate_limit_per_token_per_s": 1.0,
        "rate_limit_burst": 3,
        "planner_enabled": False,
        "login_attempts_per_minute": 3.0,
    }
    with (
        live_server(seeded_database_url, **settings) as base,
        httpx.Client(base_url=base, timeout=30) as client,
    ):
        yield client


def test_every_kind_of_response_carries_the_security_headers(
    api: httpx.Client, seeded_engine: Engine
) -> None:
    token = issue(seeded_engine, "vehicle", "SF-001")
    answers = {
        "fast ping path": api.post("/api/v1/pings", json=ping("SF-001"), headers=bearer(token)),
        "API route": api.get("/api/v1/vehicles/SF-001/config", headers=bearer(token)),
        "API error": api.get("/api/v1/fleet"),
        "dashboard": api.get("/login"),
        "health": api.get("/healthz"),
    }
    for kind, answer in answers.items():
        assert answer.headers["x-content-type-options"] == "nosniff", kind
        assert answer.headers["x-frame-options"] == "DENY", kind
        policy = answer.headers["content-security-policy"]
        assert "script-src 'self';" in policy, kind
        assert "frame-ancestors 'none'" in policy, kind
        # kept by no browser or proxy: a shared computer's cache showed the next user the
        # fleet's state (security audit)
        assert answer.headers["cache-control"] == "no-store", kind
    assert answers["fast ping path"].status_code == 200
    asset = api.get("/static/dashboard.js")
    assert asset.status_code == 200
    assert "no-store" not in asset.headers.get("cache-control", "")


def test_api_docs_are_served_from_local_assets(api: httpx.Client) -> None:
    page = api.get("/docs")
    assert page.status_code == 200
    assert "/static/apidocs/swagger-ui-bundle.js" in page.text
    assert "cdn." not in page.text
    assert "'unsafe-inline'" in page.headers["content-security-policy"]
    assert api.get("/static/apidocs/swagger-ui-bundle.js").status_code == 200
    redoc = api.get("/redoc")
    assert "/static/apidocs/redoc.standalone.js" in redoc.text
    assert "fonts.googleapis" not in redoc.text


def test_a_token_past_its_rate_gets_429_on_pings_and_on_other_routes(
    api: httpx.Client, seeded_engine: Engine
) -> None:
    token = issue(seeded_engine, "vehicle", "SF-002")
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(minutes=30)
    statuses = [
        api.post(
            "/api/v1/pings",
            json=ping("SF-002", start + timedelta(seconds=n)),
            headers=bearer(token),
        ).status_code
        for n in range(3)
    ]
    assert statuses == [200, 200, 200]  # the burst
    refused = api.post("/api/v1/pings", json=ping("SF-002", start), headers=bearer(token))
    assert refused.status_code == 429
    assert refused.json() == {"detail": "too many requests for this token"}
    assert refused.headers["Retry-After"] == "1"
    route = api.get("/api/v1/vehicles/SF-002/config", headers=bearer(token))
    assert route.status_code == 429
    assert route.json() == {"detail": "too many requests for this token"}
    # Another car's token is not affected.
    other = issue(seeded_engine, "vehicle", "SF-003")
    assert api.get("/api/v1/vehicles/SF-003/config", headers=bearer(other)).status_code == 200


def test_login_attempts_from_one_address_are_limited(
    api: httpx.Client, seeded_engine: Engine
) -> None:
    add_users(seeded_engine)
    # Different accounts, so the per-account slowdown does not kick in; the address limit does.
    for role in ("viewer", "operator", "admin"):
        assert log_in(api, role, "wrong password").status_code == 401
    limited = log_in(api, "admin", PASSWORDS["admin"])
    assert limited.status_code == 429
    assert "Too many login attempts" in limited.text
    assert int(limited.headers["Retry-After"]) >= 1


@pytest.mark.slow
def test_secrets_never_reach_the_logs(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path
) -> None:
    add_users(seeded_engine)
    token = issue(seeded_engine, "vehicle", "SF-004")
    secrets = {
        "inrix key": "inrix-key-4f7c1d9e2b",
        "secret key": "session-signing-key-8a1b2c3d4e5f6a7b8c9d",
        "vehicle token": token,
        "password": PASSWORDS["operator"],
        "bogus token": "sf_bogus-token-that-was-tried-9x8y7z",
    }
    port = free_port()
    env = cli_env(
        SMOOTHFLEET_DATABASE_URL=seeded_database_url,
        SMOOTHFLEET_PORT=str(port),
        SMOOTHFLEET_INRIX_KEY=secrets["inrix key"],
        SMOOTHFLEET_SECRET_KEY=secrets["secret key"],
        SMOOTHFLEET_PLANNER_ENABLED="false",
    )
    log_file = tmp_path / "serve.log"
    with log_file.open("w") as log:
        server = subprocess.Popen(
            [*smoothfleet_command(), "serve", "--no-migrate"],
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    base = f"http://127.0.0.1:{port}"
    try:
        wait_until_ready(base)
        with httpx.Client(base_url=base, timeout=30) as client:
            client.post("/api/v1/pings", json=ping("SF-004"), headers=bearer(token))
            client.post("/api/v1/pings", json=ping("SF-005"), headers=bearer(token))  # 403
            client.post(
                "/api/v1/pings", json=ping("SF-004"), headers=bearer(secrets["bogus token"])
            )
            client.post("/api/v1/pings", content=b"{not json", headers=bearer(token))
            client.get("/api/v1/fleet", headers=bearer(secrets["bogus token"]))
            log_in(client, "operator", "a wrong " + secrets["password"])
            log_in(client, "operator", secrets["password"])
    finally:
        stop_gracefully(server, log_file)
    logged = log_file.read_text()
    assert "Uvicorn running" in logged  # the log was captured
    for name, secret in secrets.items():
        assert secret not in logged, f"the {name} appears in the server log"
