"""A 200 means committed: kill the server with SIGKILL mid-stream, every acknowledged ping stays."""

from __future__ import annotations

import signal
import subprocess
import threading
import time
from datetime import UTC, datetime, timedelta

import httpx
import pytest
from sqlalchemy import Engine, text

from tests.support.api import ping
from tests.support.servers import cli_env, free_port, smoothfleet_command, wait_until_ready
from tests.support.tokens import bearer, issue

STREAMS = 6  # concurrent uploaders, like cars posting at once
KILL_AFTER_ACKS = 300


@pytest.mark.slow
def test_every_acknowledged_ping_survives_a_sigkill_of_the_server(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    headers = bearer(issue(seeded_engine, "operator"))
    port = free_port()
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url, SMOOTHFLEET_PORT=str(port))
    server = subprocess.Popen(
        [*smoothfleet_command(), "serve", "--no-migrate"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    base = f"http://127.0.0.1:{port}"
    acknowledged: list[tuple[str, str]] = []
    failures: list[str] = []
    lock = threading.Lock()
    stop = threading.Event()

    def upload(stream: int) -> None:
        vehicle = f"SF-{stream + 1:03d}"
        start = datetime.now(UTC).replace(microsecond=0) - timedelta(hours=1)
        with httpx.Client(base_url=base, timeout=10) as client:
            for second in range(100_000):
                if stop.is_set():
                    return
                # Alternate single pings and small store-and-forward batches.
                count = 1 if second % 2 else 5
                pings = [
                    ping(vehicle, start + timedelta(seconds=second * 5 + k)) for k in range(count)
                ]
                try:
                    answer = client.post("/api/v1/pings", json={"pings": pings}, headers=headers)
                except httpx.HTTPError as error:
                    with lock:
                        failures.append(type(error).__name__)
                    return
                if answer.status_code == 200:
                    assert answer.json()["accepted"] == count
                    with lock:
                        acknowledged.extend((p["vehicle_id"], p["ts"]) for p in pings)

    try:
        wait_until_ready(base)
        uploaders = [threading.Thread(target=upload, args=(n,)) for n in range(STREAMS)]
        for thread in uploaders:
            thread.start()
        deadline = time.monotonic() + 60
        while len(acknowledged) < KILL_AFTER_ACKS and time.monotonic() < deadline:
            time.sleep(0.01)
        server.send_signal(signal.SIGKILL)
        server.wait(timeout=10)
        for thread in uploaders:
            thread.join(timeout=30)
    finally:
        stop.set()
        if server.poll() is None:
            server.kill()
            server.wait()

    assert len(acknowledged) >= KILL_AFTER_ACKS
    assert failures, "the kill should have cut uploads off mid-stream"
    with seeded_engine.connect() as connection:
        rows = connection.execute(text("SELECT vehicle_id, ts FROM fact_vehicle_ping")).all()
    stored = {(vehicle_id, ts.isoformat()) for vehicle_id, ts in rows}
    missing = set(acknowledged) - stored
    assert not missing, f"{len(missing)} acknowledged pings lost, e.g. {sorted(missing)[:3]}"
