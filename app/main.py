"""The FastAPI application of the API and the in-process schedule (maintenance, planner).

The dashboard is mounted on it one level up, by `smoothfleet.server`: `dashboards` uses `app`'s
services, so `app` must not import `dashboards` back.
"""

from __future__ import annotations

import gc
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from apscheduler.schedulers.asyncio import AsyncIOScheduler
from fastapi import FastAPI
from sqlalchemy.ext.asyncio import async_sessionmaker
from uvicorn.middleware.proxy_headers import ProxyHeadersMiddleware

from app.auth import TokenCache
from app.core.body_limit import BodySizeLimit
from app.core.config import Settings, SettingsError, get_settings
from app.core.db import make_async_engine
from app.core.deadline import PROBE_TIMEOUT_S, DatabaseWatch, RequestDeadline
from app.core.errors import install_error_handlers
from app.core.headers import SecurityHeaders, install_api_docs
from app.core.metrics import RequestMetrics
from app.corridors.router import router as corridors_router
from app.feeds.router import router as feeds_router
from app.fleet.router import router as fleet_router
from app.health.router import router as health_router
from app.ingest import PingFastPath, ingest_running
from app.maintenance import maintain_async
from app.plans.jobs import schedule_planner
from app.plans.router import router as plans_router
from app.plans.service import HeldPlans, PlanDocuments
from app.policies.router import router as policies_router
from app.vehicles.router import router as vehicles_router

log = logging.getLogger(__name__)

MAINTENANCE_PERIOD_S = 3600


def freeze_startup_heap() -> None:
    """Take what start-up built out of the garbage collector's sight.

    A worker holds ~150,000 long-lived objects once its modules (FastAPI, pydantic, SQLAlchemy,
    numpy, the planner) are imported. CPython's full (generation 2) collection walks all of
    them, and under ingest load one ran every few seconds, holding the event loop 40-70 ms on
    an idle core and several hundred ms on a busy one: every request in flight waited (the
    p99.9 of bench/ingest.py; found with gc.callbacks, docs/performance.md). Frozen objects are
    never scanned again; a collection then walks only what serving created since.
    """
    gc.collect()
    gc.freeze()


def create_api(settings: Settings | None = None) -> FastAPI:
    """Build the API for the database named in the settings."""
    settings = settings or get_settings()
    if settings.database_url is None:
        raise SettingsError(
            "SMOOTHFLEET_DATABASE_URL: the server process needs it (the smoothfleet CLI sets it "
            "to the embedded PostgreSQL when you run `smoothfleet serve`)"
        )
    database_url = settings.database_url

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        engine = make_async_engine(
            database_url,
            pool_size=settings.db_pool_size,
            connect_timeout_s=settings.db_connect_timeout_s,
            statement_timeout_s=settings.db_statement_timeout_s,
        )
        app.state.engine = engine
        app.state.sessionmaker = async_sessionmaker(engine, expire_on_commit=False)
        scheduler = AsyncIOScheduler(timezone="UTC")
        app.state.scheduler = scheduler

        async def run_maintenance() -> None:
            try:
                async with engine.begin() as connection:
                    result = await maintain_async(
                        connection,
                        ahead_days=settings.ping_partitions_ahead_days,
                        retention_days=settings.ping_retention_days,
                    )
                log.info("maintenance: %s", result)
            except Exception:
                log.exception("maintenance pass failed; the next one retries")

        await run_maintenance()
        scheduler.add_job(
            run_maintenance,
            "interval",
            seconds=MAINTENANCE_PERIOD_S,
            id="maintenance",
            max_instances=1,
            coalesce=True,
        )
        stop_planner = (
            schedule_planner(scheduler, database_url, settings)
            if settings.planner_enabled
            else None
        )
        scheduler.start()
        try:
            async with ingest_running(app, engine, settings):
                freeze_startup_heap()
                yield
        finally:
            scheduler.shutdown(wait=False)
            if stop_planner is not None:
                stop_planner()
            token_cache: TokenCache | None = getattr(app.state, "token_cache", None)
            if token_cache is not None:
                await token_cache.close(settings.db_connect_timeout_s)
            await engine.dispose()
            await app.state.database_watch.close()

    app = FastAPI(
        title="smoothfleet",
        version="1",
        summary="Traffic-smoothing fleet: pings, INRIX feed, speed plans, fleet health.",
        lifespan=lifespan,
        docs_url=None,
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.plan_documents = PlanDocuments()
    app.state.held_plans = HeldPlans()
    install_error_handlers(app)
    app.add_middleware(PingFastPath)
    database_watch = DatabaseWatch(database_url, PROBE_TIMEOUT_S)
    app.state.database_watch = database_watch
    app.add_middleware(RequestDeadline, deadline_s=settings.api_deadline_s, watch=database_watch)
    app.add_middleware(BodySizeLimit, max_bytes=settings.max_body_bytes)
    app.add_middleware(RequestMetrics)
    app.add_middleware(SecurityHeaders)
    if settings.trusted_proxies.strip():
        # Outermost, so every layer sees the client's address and scheme as the proxy saw them.
        app.add_middleware(ProxyHeadersMiddleware, trusted_hosts=settings.trusted_proxies)
    install_api_docs(app)
    app.include_router(health_router)
    app.include_router(vehicles_router)
    app.include_router(corridors_router)
    app.include_router(feeds_router)
    app.include_router(fleet_router)
    app.include_router(plans_router)
    app.include_router(policies_router)
    return app
