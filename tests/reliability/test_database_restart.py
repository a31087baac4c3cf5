"""PostgreSQL restarts under load: the API answers 503 meanwhile (not 500, never hanging),
recovers by itself, and every acknowledged ping is stored.

The test runs its own embedded PostgreSQL cluster (not the session's) so it can stop and start
it, and `smoothfleet serve` as a process, with cars streaming pings into it.
"""

from __future__ import annotations

import subprocess
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import pytest
from sqlalchemy import text

from app.core.db import make_sync_engine
from tests.reliability.conftest import Cluster
from tests.support.api import ping
from tests.support.servers import (
    cli_env,
    free_port,
    smoothfleet_command,
    stop_gracefully,
    wait_until_ready,
)
from tests.support.tokens import bearer, issue

CARS = 8
OUTAGE_S = 4.0
# A request must be answered within this, outage or not (the pool and connect timeouts are 5 s).
ANSWER_WITHIN_S = 15.0


@dataclass
class Stream:
    """What the cars saw."""

    acknowledged: list[tuple[str, str]] = field(default_factory=list)
    statuses: Counter[int] = field(default_factory=Counter)
    retry_after: set[str] = field(default_factory=set)
    slowest_s: float = 0.0
    errors: list[str] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)


def drive(base: str, vehicle: str, token: str, stream: Stream, stop: threading.Event) -> None:
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(hours=2)
    with httpx.Client(base_url=base, timeout=ANSWER_WITHIN_S + 5) as client:
        for second in range(100_000):
            if stop.is_set():
                return
            body = ping(vehicle, start + timedelta(seconds=second))
            began = time.monotonic()
            try:
                answer = client.post("/api/v1/pings", json=body, headers=bearer(token))
            except httpx.HTTPError as error:
                with stream.lock:
                    stream.errors.append(repr(error))
                return
            took = time.monotonic() - began
            with stream.lock:
                stream.slowest_s = max(stream.slowest_s, took)
                stream.statuses[answer.status_code] += 1
                if answer.status_code == 200 and answer.json()["accepted"] == 1:
                    stream.acknowledged.append((vehicle, body["ts"]))
                if answer.status_code == 503:
                    stream.retry_after.add(answer.headers.get("Retry-After", ""))
            # Ten pings a second per car: well inside the per-token rate limit (a real car
            # sends one), so every refusal seen here is the outage's.
            time.sleep(0.1)


@pytest.mark.slow
def test_a_database_restart_under_load_is_503_then_recovers_without_loss(
    cluster: Cluster, tmp_path: Path
) -> None:
    engine = make_sync_engine(cluster.url)
    tokens = {f"SF-{n:03d}": issue(engine, "vehicle", f"SF-{n:03d}") for n in range(1, CARS + 1)}
    engine.dispose()
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    with (tmp_path / "serve.log").open("w") as log:
        server = subprocess.Popen(
            [*smoothfleet_command(), "serve", "--no-migrate", "--no-planner"],
            env=cli_env(SMOOTHFLEET_DATABASE_URL=cluster.url, SMOOTHFLEET_PORT=str(port)),
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    stream, stop = Stream(), threading.Event()
    cars = [
        threading.Thread(target=drive, args=(base, vehicle, token, stream, stop))
        for vehicle, token in tokens.items()
    ]
    try:
        wait_until_ready(base)
        for car in cars:
            car.start()
        time.sleep(2)
        before_outage = len(stream.acknowledged)
        cluster.stop()
        time.sleep(OUTAGE_S)
        during_outage = Counter(stream.statuses)
        cluster.start()
        # Recovery by itself: acknowledgements resume without touching the API.
        deadline = time.monotonic() + 60
        resumed_at = len(stream.acknowledged)
        while len(stream.acknowledged) < resumed_at + 50 and time.monotonic() < deadline:
            time.sleep(0.1)
        stop.set()
        for car in cars:
            car.join(timeout=60)
    finally:
        stop.set()
        stop_gracefully(server, tmp_path / "serve.log")

    server_log = (tmp_path / "serve.log").read_text()
    assert not stream.errors, stream.errors[:3]
    assert before_outage > 0
    assert during_outage[503] > 0, f"no 503 seen while the database was down: {during_outage}"
    assert set(stream.statuses) <= {200, 503}, f"{stream.statuses}\n{server_log[-3000:]}"
    assert stream.retry_after == {"5"}
    assert stream.slowest_s < ANSWER_WITHIN_S
    assert len(stream.acknowledged) >= resumed_at + 50, "the API did not recover by itself"

    engine = make_sync_engine(cluster.url)
    with engine.connect() as connection:
        rows = connection.execute(text("SELECT vehicle_id, ts FROM fact_vehicle_ping")).all()
    engine.dispose()
    stored = {(vehicle_id, ts.isoformat()) for vehicle_id, ts in rows}
    missing = set(stream.acknowledged) - stored
    assert not missing, f"{len(missing)} acknowledged pings lost, e.g. {sorted(missing)[:3]}"
