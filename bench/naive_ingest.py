"""The baseline of bench/ingest.py: a plain FastAPI handler doing one INSERT per request.

What a first version of the ping endpoint looks like: FastAPI parses and validates the ping,
a session from the app's engine inserts it (ON CONFLICT DO NOTHING) and commits, and the answer
has the interface's shape. No authentication, map-matching or grouping.

    SMOOTHFLEET_DATABASE_URL=... uvicorn bench.naive_ingest:create_app --factory
"""

from __future__ import annotations

import os
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from sqlalchemy import text
from sqlalchemy.ext.asyncio import async_sessionmaker

from app.core.db import SessionDep, make_async_engine
from contract.vehicles import Ping

INSERT_ONE = text(
    """
    INSERT INTO fact_vehicle_ping (
        vehicle_id, ts, lat, lon, speed_mps, accel_mps2, heading_deg, lane,
        is_acc_engaged, is_controller_engaged, controller, acc_speed_setting_mph,
        acc_gap_setting, is_lead_present, lead_distance_m, lead_rel_speed_mps, plan_id
    ) VALUES (
        :vehicle_id, :ts, :lat, :lon, :speed_mps, :accel_mps2, :heading_deg, :lane,
        :acc_engaged, :controller_engaged, :controller, :acc_speed_setting_mph,
        :acc_gap_setting, :lead_present, :lead_distance_m, :lead_rel_speed_mps, :plan_id
    )
    ON CONFLICT (vehicle_id, ts) DO NOTHING
    RETURNING 1
    """
)


def create_app() -> FastAPI:
    """The baseline app on SMOOTHFLEET_DATABASE_URL."""
    url = os.environ["SMOOTHFLEET_DATABASE_URL"]

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        engine = make_async_engine(url, pool_size=10)
        app.state.sessionmaker = async_sessionmaker(engine, expire_on_commit=False)
        yield
        await engine.dispose()

    app = FastAPI(lifespan=lifespan)

    @app.post("/api/v1/pings")
    async def post_ping(ping: Ping, session: SessionDep) -> dict[str, object]:
        inserted = (await session.execute(INSERT_ONE, ping.model_dump())).first() is not None
        return {"accepted": int(inserted), "duplicates": int(not inserted), "rejected": []}

    return app
