"""A car offline for a long stretch (20 minutes without the server), then back: every ping it
spooled reaches the database exactly once, oldest first, in batches the API accepts."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import pytest
from sqlalchemy import Engine, text

from sim.emulator.rig import rig
from tests.support.servers import free_port, live_server
from tests.support.tokens import issue
from vehicle_agent.server import ServerClient
from vehicle_agent.spool import PingSpool

OFFLINE_S = 20 * 60


@pytest.mark.slow
def test_twenty_minutes_offline_then_every_spooled_ping_arrives_once(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path, dbc_cache: Path
) -> None:
    token = issue(seeded_engine, "vehicle", "SF-005")
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(hours=1)
    nowhere = f"http://127.0.0.1:{free_port()}"  # nothing listens: connection refused
    with (
        httpx.Client(base_url=nowhere) as offline,
        rig(
            "nissan_rogue",
            tmp_path,
            dbc_cache,
            controller="unused",
            vehicle_id="SF-005",
            speed_mps=11.0,  # stays on the 14.6 km corridor for the 20 minutes
            server=ServerClient(offline, "SF-005", token, timeout_s=0.2),
            start=start,
            spool=PingSpool(tmp_path / "spool.sqlite"),
        ) as car,
    ):
        car.run(OFFLINE_S, network=True)
        backlog = car.agent.spool.backlog()
        assert backlog == OFFLINE_S  # one ping a second, none lost, none sent
        assert car.agent.stats.server_errors["pings"] >= 1
        spooled = [ping["ts"] for _, ping in car.agent.spool.oldest(backlog)]
        with (
            live_server(seeded_database_url, planner_enabled=False) as base,
            httpx.Client(base_url=base) as online,
        ):
            car.agent.server = ServerClient(online, "SF-005", token)
            uploaded = 0
            while car.agent.spool.backlog():
                sent = car.agent.upload()
                assert sent > 0
                uploaded += sent
            # A second drain finds nothing to send twice.
            assert car.agent.upload() == 0
        assert uploaded == backlog
    with seeded_engine.connect() as connection:
        stored = connection.execute(
            text("SELECT ts FROM fact_vehicle_ping WHERE vehicle_id = 'SF-005' ORDER BY ts")
        ).scalars()
        stored_ts = list(stored)
    assert len(stored_ts) == backlog
    assert stored_ts == sorted(datetime.fromisoformat(ts) for ts in spooled)
