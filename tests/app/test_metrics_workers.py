"""With several workers, /metrics counts every worker's pings, whichever worker answers."""

from __future__ import annotations

import subprocess
from pathlib import Path

import httpx
import pytest
from sqlalchemy import Engine

from tests.support.api import ping
from tests.support.servers import (
    cli_env,
    free_port,
    smoothfleet_command,
    stop_gracefully,
    wait_until_ready,
)
from tests.support.tokens import bearer, issue


def accepted(text: str) -> float:
    for line in text.splitlines():
        if line.startswith('smoothfleet_pings_total{outcome="accepted"}'):
            return float(line.rsplit(" ", 1)[1])
    return 0.0


@pytest.mark.slow
def test_two_workers_report_one_sum(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path
) -> None:
    headers = bearer(issue(seeded_engine, "operator"))
    port = free_port()
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url, SMOOTHFLEET_PORT=str(port))
    log = tmp_path / "serve.log"
    with log.open("w") as log_file:
        server = subprocess.Popen(
            [*smoothfleet_command(), "serve", "--no-migrate", "--no-planner", "--workers", "2"],
            env=env,
            stdout=log_file,
            stderr=log_file,
        )
    base = f"http://127.0.0.1:{port}"
    try:
        try:
            wait_until_ready(base, timeout_s=180)
        except TimeoutError:
            pytest.fail(f"server did not start: {log.read_text()[-2000:]}")
        for _ in range(40):  # a new connection each time: the kernel spreads them over workers
            answer = httpx.post(f"{base}/api/v1/pings", json=ping(), headers=headers, timeout=30)
            assert answer.json()["accepted"] == 1
        scrapes = [accepted(httpx.get(f"{base}/metrics", timeout=30).text) for _ in range(6)]
    finally:
        stop_gracefully(server, log)
    assert scrapes == [40.0] * 6
