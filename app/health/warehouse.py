"""Gauges read from the warehouse at scrape time: whether plans and INRIX keep arriving,
whichever process makes them.

The planner's own counters (`app.plans.metrics`) live in the process that runs the schedule,
and `smoothfleet inrix poll` writes readings straight to the database. In the compose layout
(`planner run` and the poller as their own services, neither serving HTTP) the API's /metrics
never saw a planner run or a polled reading, so on-call could not alert on a stalled planner or
feed (ops audit). These figures come from the tables both write, per corridor, by indexed
reads: the newest published plan (`ix_plan_run_corridor_id_published_at`), the newest run and
its status (the primary key), the newest INRIX reading (`ix_fact_inrix_estimate_...`).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.core import GaugeMetricFamily
from prometheus_client.registry import Collector
from sqlalchemy import text
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.ext.asyncio import AsyncEngine

NEWEST_PER_CORRIDOR = text(
    """
    SELECT c.corridor_id,
           (SELECT max(p.published_at) FROM plan_run p
             WHERE p.corridor_id = c.corridor_id AND p.status = 'published') AS published_at,
           newest.started_at AS run_started_at,
           newest.status AS run_status,
           (SELECT max(e.measured_at) FROM fact_inrix_estimate e
             WHERE e.corridor_id = c.corridor_id) AS inrix_measured_at
    FROM dim_corridor c
    LEFT JOIN LATERAL (
        SELECT r.started_at, r.status FROM plan_run r
        WHERE r.corridor_id = c.corridor_id ORDER BY r.plan_id DESC LIMIT 1
    ) newest ON true
    ORDER BY c.corridor_id
    """
)


class _Newest(Collector):
    """The rows of NEWEST_PER_CORRIDOR as gauges (None: the database did not answer)."""

    def __init__(self, rows: Sequence[tuple[Any, ...]] | None):
        self.rows = rows

    def collect(self) -> Iterator[GaugeMetricFamily]:
        up = GaugeMetricFamily(
            "smoothfleet_warehouse_up", "1 when the warehouse answered this scrape's reads."
        )
        up.add_metric([], 0.0 if self.rows is None else 1.0)
        yield up
        if self.rows is None:
            return
        published = GaugeMetricFamily(
            "smoothfleet_warehouse_plan_published_timestamp_seconds",
            "Unix time of the newest published plan, by corridor (whichever process planned).",
            labels=["corridor"],
        )
        run = GaugeMetricFamily(
            "smoothfleet_warehouse_plan_run_timestamp_seconds",
            "Unix start time of the newest planner run, by corridor and that run's status.",
            labels=["corridor", "status"],
        )
        inrix = GaugeMetricFamily(
            "smoothfleet_warehouse_inrix_measured_timestamp_seconds",
            "Unix time of the newest INRIX reading stored, by corridor (API or poller).",
            labels=["corridor"],
        )
        for corridor, published_at, run_started_at, run_status, inrix_measured_at in self.rows:
            if published_at is not None:
                published.add_metric([corridor], published_at.timestamp())
            if run_started_at is not None:
                run.add_metric([corridor, run_status], run_started_at.timestamp())
            if inrix_measured_at is not None:
                inrix.add_metric([corridor], inrix_measured_at.timestamp())
        yield from (published, run, inrix)


async def warehouse_exposition(engine: AsyncEngine) -> bytes:
    """The gauges' Prometheus text; `smoothfleet_warehouse_up 0` alone when the database does
    not answer (/readyz says why)."""
    rows: list[tuple[Any, ...]] | None
    try:
        async with engine.connect() as connection:
            rows = [tuple(row) for row in await connection.execute(NEWEST_PER_CORRIDOR)]
    except (SQLAlchemyError, OSError):
        rows = None
    registry = CollectorRegistry(auto_describe=False)
    registry.register(_Newest(rows))
    return generate_latest(registry)
