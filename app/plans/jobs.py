"""The planner as a job: one cycle per corridor, logged, counted, never fatal to its schedule.

Used by `smoothfleet planner once|run` and by the schedule inside `smoothfleet serve`. Each
corridor's cycle is one transaction (planner.warehouse.run_cycle), its window's per-vehicle
observations a second one right after publication; a failing cycle is rolled
back, logged with its traceback, recorded as a `failed` plan_run and counted in /metrics, and
the last good plan simply ages out (valid_until) so vehicles fall back to their stock ACC.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import Engine

from app.core.config import Settings
from app.core.db import make_sync_engine, session_scope
from app.plans import metrics
from planner import parse_params
from planner.warehouse import (
    CycleOutcome,
    corridor_ids,
    record_failure,
    run_cycle,
    store_window_observations,
)

log = logging.getLogger(__name__)

PLANNER_JOB_ID = "planner"


def run_planner(
    engine: Engine,
    settings: Settings,
    *,
    corridors: list[str] | None = None,
    min_interval_s: float = 0.0,
    now: datetime | None = None,
) -> list[CycleOutcome]:
    """One cycle for each corridor (all of them unless named), each in its own transaction."""
    algorithm = settings.planner_algorithm
    params = parse_params(settings.planner_param_values())
    if corridors is None:
        with session_scope(engine) as session:
            corridors = corridor_ids(session)
    outcomes = []
    for corridor_id in corridors:
        started_at = now or datetime.now(UTC)
        clock = time.perf_counter()
        try:
            with session_scope(engine) as session:
                outcome = run_cycle(
                    session,
                    corridor_id,
                    algorithm=algorithm,
                    params=params,
                    valid_for_s=settings.plan_valid_for_s,
                    now=started_at,
                    min_interval_s=min_interval_s,
                )
        except Exception as error:
            log.exception("planner cycle for %s failed; the last good plan ages out", corridor_id)
            reason = f"{type(error).__name__}: {error}".splitlines()[0]
            outcome = CycleOutcome(corridor_id, "failed", reason=reason)
            try:
                with session_scope(engine) as session:
                    plan_id = record_failure(
                        session,
                        corridor_id,
                        algorithm=algorithm,
                        params=params,
                        started_at=started_at,
                        reason=reason,
                    )
                outcome = CycleOutcome(corridor_id, "failed", plan_id, reason)
            except Exception:
                log.exception("could not record the failed planner cycle for %s", corridor_id)
        metrics.PLANNER_RUN_SECONDS.observe(time.perf_counter() - clock)
        _count(outcome)
        try:
            with session_scope(engine) as session:
                store_window_observations(session, outcome)
        except Exception:
            log.exception("could not store the window's observations for %s", corridor_id)
        outcomes.append(outcome)
    return outcomes


def _count(outcome: CycleOutcome) -> None:
    corridor = outcome.corridor_id
    metrics.PLANNER_RUNS.labels(corridor, outcome.status).inc()
    if outcome.status == "published":
        metrics.PLANNER_LAST_PUBLISHED.labels(corridor).set(time.time())
        log.info(
            "planner: published plan %s for %s in %.0f ms (%s vehicles, %s pings, INRIX %s s "
            "old, its oldest reading in use %s s)",
            outcome.plan_id,
            corridor,
            outcome.duration_ms,
            outcome.inputs.get("vehicles"),
            outcome.inputs.get("pings"),
            outcome.inputs.get("inrix_age_s"),
            outcome.inputs.get("inrix_oldest_reading_age_s"),
        )
    elif outcome.status == "skipped":
        log.warning("planner: no plan for %s: %s", corridor, outcome.reason)
    elif outcome.status == "busy":
        log.info("planner: %s left alone: %s", corridor, outcome.reason)
    ignored: dict[str, Any] = outcome.inputs.get("inrix_ignored", {})
    for reason, count in ignored.items():
        metrics.PLANNER_INRIX_IGNORED.labels(corridor, reason).set(count)
    if "pings" in outcome.inputs:
        metrics.PLANNER_INPUT_PINGS.labels(corridor, "on_corridor").set(outcome.inputs["pings"])
        metrics.PLANNER_INPUT_PINGS.labels(corridor, "off_corridor").set(
            outcome.inputs["pings_off_corridor"]
        )
        metrics.PLANNER_INPUT_PINGS.labels(corridor, "set_aside").set(
            outcome.inputs["pings_set_aside"]
        )


def schedule_planner(scheduler: Any, database_url: str, settings: Settings) -> Callable[[], None]:
    """Add the planner to an APScheduler every SMOOTHFLEET_PLANNER_PERIOD_S; returns a cleanup.

    The first cycle runs as the scheduler starts, not a period later: after a restart the
    fleet's plan (valid for SMOOTHFLEET_PLAN_VALID_FOR_S) would otherwise age for a whole
    period more before the next one, and a server started from cold would have none. An
    overrunning cycle is not started twice (max_instances=1) and missed runs collapse into
    one (coalesce). Replicas and workers each schedule it, first cycles at once included; the
    advisory lock and `min_interval_s` (half a period) leave one plan per corridor and period.
    """
    engine = make_sync_engine(
        database_url,
        connect_timeout_s=settings.db_connect_timeout_s,
        statement_timeout_s=max(settings.db_statement_timeout_s, settings.planner_period_s),
    )

    def cycle() -> None:
        try:
            run_planner(engine, settings, min_interval_s=settings.planner_period_s / 2)
        except Exception:
            log.exception("planner schedule: the cycle could not run; the next one retries")

    scheduler.add_job(
        cycle,
        "interval",
        seconds=settings.planner_period_s,
        id=PLANNER_JOB_ID,
        max_instances=1,
        coalesce=True,
        misfire_grace_time=int(settings.planner_period_s),
        next_run_time=datetime.now(UTC),
    )
    return engine.dispose
