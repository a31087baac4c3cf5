"""`smoothfleet planner run | once | replay`: the Speed Planner from the command line.

`run` is the schedule in its own process (every SMOOTHFLEET_PLANNER_PERIOD_S, first run at
once; Ctrl-C stops it), `once` one cycle per corridor, `replay --plan-id N` recomputes a stored
plan from the warehouse and says whether it matches (exit code 1 when it does not).
"""

from __future__ import annotations

import logging
from datetime import UTC, datetime
from typing import Any

import click

from app.core.config import Settings
from planner.warehouse import CycleOutcome, UnknownPlan, corridor_ids


def describe(outcome: CycleOutcome) -> str:
    """One line for a cycle's outcome."""
    if outcome.status == "published":
        inputs = outcome.inputs
        return (
            f"{outcome.corridor_id}: published plan {outcome.plan_id} in "
            f"{outcome.duration_ms:.0f} ms ({inputs['vehicles']} vehicles, {inputs['pings']} "
            f"pings, INRIX {inputs['inrix_age_s']:.0f} s old{_carried(inputs)})"
        )
    label = {"skipped": "no plan", "failed": "failed", "busy": "left alone"}[outcome.status]
    return f"{outcome.corridor_id}: {label}: {outcome.reason}"


def _carried(inputs: dict[str, Any]) -> str:
    """', its oldest reading N s' when segments the newest snapshot did not read stand on
    older readings (a partial outage), else nothing."""
    oldest = inputs.get("inrix_oldest_reading_age_s")
    if oldest is None or oldest - inputs["inrix_age_s"] < 1:
        return ""
    return f", some segments' reading {oldest:.0f} s old"


@click.group("planner")
def planner() -> None:
    """The Speed Planner: its schedule, a single cycle, and replay of a stored plan."""


def _check_corridors(url: str, corridors: tuple[str, ...]) -> None:
    """Fail with one line when a named corridor is not in the warehouse."""
    from app.core.db import make_sync_engine, session_scope
    from smoothfleet.cli.common import CliError

    engine = make_sync_engine(url)
    try:
        with session_scope(engine) as session:
            known = corridor_ids(session)
    finally:
        engine.dispose()
    unknown = [corridor for corridor in corridors if corridor not in known]
    if unknown:
        raise CliError(
            f"planner: unknown corridor {', '.join(unknown)} (known: {', '.join(known) or 'none'})"
        )


def _cycle(url: str, current: Settings, corridors: tuple[str, ...], min_interval_s: float) -> int:
    from app.core.db import make_sync_engine
    from app.plans.jobs import run_planner
    from smoothfleet.cli.common import console

    engine = make_sync_engine(url)
    try:
        outcomes = run_planner(
            engine, current, corridors=list(corridors) or None, min_interval_s=min_interval_s
        )
    finally:
        engine.dispose()
    for outcome in outcomes:
        console.print(describe(outcome), highlight=False)
    return sum(outcome.status == "failed" for outcome in outcomes)


@planner.command("once")
@click.option("--corridor", "corridors", multiple=True, help="Only this corridor (repeatable).")
def once(corridors: tuple[str, ...]) -> None:
    """Run one planner cycle for every corridor (or those named) and publish."""
    from smoothfleet.cli.common import database, settings

    current = settings()
    with database(current) as url:
        _check_corridors(url, corridors)
        failed = _cycle(url, current, corridors, 0.0)
    if failed:
        raise SystemExit(1)


@planner.command("run")
@click.option("--corridor", "corridors", multiple=True, help="Only this corridor (repeatable).")
def run(corridors: tuple[str, ...]) -> None:
    """Run the planner every SMOOTHFLEET_PLANNER_PERIOD_S seconds until stopped."""
    from apscheduler.schedulers.blocking import BlockingScheduler

    from smoothfleet.cli.common import console, database, settings

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s %(message)s")
    current = settings()
    with database(current) as url:
        _check_corridors(url, corridors)
        scheduler = BlockingScheduler(timezone="UTC")
        scheduler.add_job(
            _cycle,
            "interval",
            args=(url, current, corridors, current.planner_period_s / 2),
            seconds=current.planner_period_s,
            next_run_time=datetime.now(UTC),
            max_instances=1,
            coalesce=True,
            misfire_grace_time=int(current.planner_period_s),
        )
        console.print(
            f"planner: every {current.planner_period_s:g} s, algorithm "
            f"{current.planner_algorithm} (Ctrl-C stops)"
        )
        try:
            scheduler.start()
        finally:
            if scheduler.running:
                scheduler.shutdown(wait=False)


@planner.command("replay")
@click.option("--plan-id", "plan_id", required=True, type=int, help="The plan to recompute.")
def replay(plan_id: int) -> None:
    """Recompute a published plan from the warehouse and report whether it matches."""
    from app.core.db import make_sync_engine, session_scope
    from planner.warehouse import replay_plan
    from smoothfleet.cli.common import CliError, console, database, settings

    with database(settings()) as url:
        engine = make_sync_engine(url)
        try:
            with session_scope(engine) as session:
                report = replay_plan(session, plan_id)
        except UnknownPlan as error:
            raise CliError(f"planner replay: {error}") from None
        finally:
            engine.dispose()
    verdict = "matches" if report.matches else "DIFFERS"
    console.print(
        f"plan {report.plan_id} ({report.corridor_id}, {report.algorithm}): recomputed "
        f"{report.cells} targets, {verdict}: largest difference "
        f"{report.max_difference_mps:.4f} m/s, {report.buffer_cells_differing} buffer cells differ",
        highlight=False,
    )
    if not report.matches:
        raise SystemExit(1)
