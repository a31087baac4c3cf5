"""`smoothfleet tokens revoke`: a revoked token is refused by a running server."""

from __future__ import annotations

import time
from datetime import UTC, datetime

import httpx
from sqlalchemy import Engine, text

from tests.support.servers import cli_env, live_server, run_cli
from tests.support.tokens import bearer, issue


def ping(vehicle_id: str) -> dict[str, object]:
    return {
        "vehicle_id": vehicle_id,
        "ts": datetime.now(UTC).isoformat(),
        "lat": 35.98,
        "lon": -86.58,
        "speed_mps": 25.0,
    }


def test_revoked_vehicle_token_is_refused_within_the_cache_lifetime(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    token = issue(seeded_engine, "vehicle", "SF-003")
    other = issue(seeded_engine, "vehicle", "SF-004")
    with live_server(seeded_database_url, token_cache_ttl_s=0.5) as base:
        first = httpx.post(f"{base}/api/v1/pings", json=ping("SF-003"), headers=bearer(token))
        assert first.status_code == 200, first.text
        result = run_cli(
            "tokens",
            "revoke",
            "--vehicle",
            "SF-003",
            env=cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url),
        )
        assert result.returncode == 0, result.stderr
        time.sleep(0.6)
        refused = httpx.post(f"{base}/api/v1/pings", json=ping("SF-003"), headers=bearer(token))
        assert refused.status_code == 401
        assert refused.json() == {"detail": "invalid or revoked token"}
        # Other vehicles' tokens are untouched.
        kept = httpx.post(f"{base}/api/v1/pings", json=ping("SF-004"), headers=bearer(other))
        assert kept.status_code == 200
    with seeded_engine.connect() as connection:
        stored = connection.execute(
            text("SELECT count(*) FROM fact_vehicle_ping WHERE vehicle_id = 'SF-003'")
        ).scalar_one()
    assert stored == 1


def test_revoke_by_the_token_itself_and_nothing_matching(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    token = issue(seeded_engine, "feed")
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    result = run_cli("tokens", "revoke", "--token-stdin", env=env, stdin=token + "\n")
    assert result.returncode == 0, result.stderr
    again = run_cli("tokens", "revoke", "--token-stdin", env=env, stdin=token + "\n")
    assert again.returncode == 1
    assert again.stderr.strip() == "smoothfleet: error: tokens revoke: no live token matches"
    listed = run_cli("tokens", "list", env=env)
    assert listed.returncode == 0
    assert token not in listed.stdout
    assert "feed" in listed.stdout
