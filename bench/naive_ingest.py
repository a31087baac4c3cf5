"""The baseline of bench/ingest.py: the plainest reasonable async FastAPI ping handler.

FastAPI parses and validates the ping; one `INSERT ... ON CONFLICT DO NOTHING` through a
psycopg async connection pool, committed (durably: the server's default synchronous_commit)
before the answer, which has the interface's shape. No authentication, map-matching or
grouping: what a competent first version of the endpoint looks like.

    SMOOTHFLEET_DATABASE_URL=... uvicorn bench.naive_ingest:create_app --factory
"""

from __future__ import annotations

import os
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from psycopg_pool import AsyncConnectionPool

from app.core.db import libpq_url
from contract.vehicles import Ping

INSERT_ONE = """
    INSERT INTO fact_vehicle_ping (
        vehicle_id, ts, lat, lon, speed_mps, accel_mps2, heading_deg, lane,
        is_acc_engaged, is_controller_engaged, controller, acc_speed_setting_mph,
        acc_gap_setting, is_lead_present, lead_distance_m, lead_rel_speed_mps, plan_id
    ) VALUES (
        %(vehicle_id)s, %(ts)s, %(lat)s, %(lon)s, %(speed_mps)s, %(accel_mps2)s,
        %(heading_deg)s, %(lane)s, %(acc_engaged)s, %(controller_engaged)s, %(controller)s,
        %(acc_speed_setting_mph)s, %(acc_gap_setting)s, %(lead_present)s, %(lead_distance_m)s,
        %(lead_rel_speed_mps)s, %(plan_id)s
    )
    ON CONFLICT (vehicle_id, ts) DO NOTHING
"""


def create_app() -> FastAPI:
    """The baseline app on SMOOTHFLEET_DATABASE_URL."""
    pool = AsyncConnectionPool(
        libpq_url(os.environ["SMOOTHFLEET_DATABASE_URL"]), min_size=10, max_size=10, open=False
    )

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        await pool.open()
        yield
        await pool.close()

    app = FastAPI(lifespan=lifespan)

    @app.post("/api/v1/pings")
    async def post_ping(ping: Ping) -> dict[str, object]:
        async with pool.connection() as connection:  # commits when the block ends
            inserted = (await connection.execute(INSERT_ONE, ping.model_dump())).rowcount == 1
        return {"accepted": int(inserted), "duplicates": int(not inserted), "rejected": []}

    return app
